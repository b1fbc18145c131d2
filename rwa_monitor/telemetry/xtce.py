"""XTCE packet definitions, read safely, and which APID each container describes.

An XTCE file (OMG's XML Telemetric and Command Exchange) is first parsed here with a
parser that resolves no entity, loads no DTD and reaches no network, and refused whole if
it declares a DTD (any ``<!DOCTYPE``: entities, external or not, have no place in XTCE) or
holds XInclude elements; ``xsi:schemaLocation`` is never fetched (nothing is validated
against a schema). Only then is it handed, as bytes, to space-packet-parser, the
reference decoder (docs/contracts.md "CCSDS space packets").

Containers are matched to packets by the CCSDS APID: a container's restriction criteria,
along its chain of base containers, must hold one equality of the APID field (the 11-bit
field at bit 5 of the primary header) and nothing else. Entries are read in sequence as
space-packet-parser reads them: an entry list with anything but parameter and container
references at their default place (``LocationInContainerInBits`` of 0 after the previous
entry), such as an ``IncludeCondition`` or a ``RepeatEntry``, is refused for the
containers that use it rather than decoded wrongly.
"""

from __future__ import annotations

from dataclasses import dataclass
import io
import os
from typing import Any
import warnings

from rwa_monitor.exceptions import TelemetrySchemaError

MAX_XTCE_BYTES = 64 * 1024 * 1024
XINCLUDE_NS = 'http://www.w3.org/2001/XInclude'
DOCTYPE = '<!DOCTYPE'
APID_BIT, APID_BITS = 5, 11
_EQUAL = ('==', 'eq')
_ENTRY_TAGS = ('ParameterRefEntry', 'ContainerRefEntry')


@dataclass(frozen=True)
class Definition:
    """A packet definition: the reference decoder's object and what the checks found.

    Attributes
    ----------
    path : str
        The XTCE file.
    spp : space_packet_parser.XtcePacketDefinition
        space-packet-parser's parsed definition (the reference decoder).
    refused : dict of str to str
        Container name -> why its entry list is not read (module docstring).
    """

    path: str
    spp: Any
    refused: dict[str, str]

    @property
    def parameters(self) -> dict[str, Any]:
        """Return parameter name -> space-packet-parser Parameter."""
        return self.spp.parameters

    @property
    def containers(self) -> dict[str, Any]:
        """Return container name -> space-packet-parser SequenceContainer."""
        return self.spp.containers

    def chain(self, name: str) -> list[Any]:
        """Return the containers from the root down to ``name`` (its base chain)."""
        chain, seen = [], set()
        while name is not None:
            if name in seen:
                raise TelemetrySchemaError(self.path, f'container {name!r}: its base '
                                           'containers form a loop')
            seen.add(name)
            container = self.containers[name]
            chain.append(container)
            name = container.base_container_name
        return chain[::-1]

    def entries(self, name: str) -> list[Any]:
        """Return the parameters of a packet of container ``name``, in packet order."""
        out: list[Any] = []
        for container in self.chain(name):
            _flatten(container, out)
        return out

    def apid(self, name: str, apid_parameter: str) -> int:
        """Return the APID that selects container ``name`` (module docstring)."""
        found: list[int] = []
        for container in self.chain(name):
            for criterion in container.restriction_criteria:
                value = _apid_equality(criterion, apid_parameter)
                if value is None:
                    raise TelemetrySchemaError(
                        self.path, f'container {name!r}: restriction {criterion!r} of '
                        f'{container.name!r} is not an equality of the APID '
                        f'({apid_parameter}); containers are matched to packets by APID')
                found.append(value)
        if len(set(found)) != 1:
            raise TelemetrySchemaError(
                self.path, f'container {name!r}: its restriction criteria give '
                f'{"no" if not found else "more than one"} APID (expected one '
                f'{apid_parameter} == N)')
        return found[0]


def _flatten(container: Any, out: list[Any]) -> None:
    from space_packet_parser.xtce.containers import SequenceContainer
    for entry in container.entry_list:
        if isinstance(entry, SequenceContainer):
            _flatten(entry, out)
        else:
            out.append(entry)


def _apid_equality(criterion: Any, apid_parameter: str) -> int | None:
    """Return N if ``criterion`` is ``APID == N`` (any XTCE spelling of it), else None."""
    from space_packet_parser.xtce import comparisons as cmp
    if isinstance(criterion, cmp.Comparison):
        pairs = [(criterion.referenced_parameter, criterion.operator, criterion.required_value)]
    elif isinstance(criterion, cmp.BooleanExpression):
        expression = criterion.expression
        if isinstance(expression, cmp.Condition):
            conditions = [expression]
        elif isinstance(expression, cmp.Anded) and not expression.ors:
            conditions = list(expression.conditions)
        else:
            return None
        if any(c.right_param is not None for c in conditions):
            return None
        pairs = [(c.left_param, c.operator, c.right_value) for c in conditions]
    else:
        return None
    if len(pairs) != 1 or pairs[0][0] != apid_parameter or pairs[0][1] not in _EQUAL:
        return None
    try:
        return int(str(pairs[0][2]), 0)
    except ValueError:
        return None


def screen(path: str | os.PathLike) -> bytes:
    """Return the bytes of an XTCE file after the safety checks (module docstring).

    Raises
    ------
    TelemetrySchemaError
        One line naming the file: not XML, too large, a DTD, an XInclude, or not XTCE.
    """
    from lxml import etree
    name = os.fspath(path)
    try:
        with open(name, 'rb') as handle:
            if os.fstat(handle.fileno()).st_size > MAX_XTCE_BYTES:
                raise TelemetrySchemaError(name, f'XTCE file larger than {MAX_XTCE_BYTES} '
                                           'bytes')
            data = handle.read()
    except OSError as err:
        raise TelemetrySchemaError(name, f'cannot read the XTCE file: '
                                   f'{err.strerror or err}') from None
    refused_dtd = TelemetrySchemaError(name, 'the XTCE file declares a DTD (<!DOCTYPE ...>): '
                                       'refused, entities and external DTDs are never loaded')
    if any(DOCTYPE.encode(codec) in data for codec in ('utf-8', 'utf-16-le', 'utf-16-be')):
        raise refused_dtd      # before parsing: its entities are never even declared
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                             dtd_validation=False, huge_tree=False)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as err:
        raise TelemetrySchemaError(name, f'not an XML file: {err}') from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None \
            or tree.docinfo.externalDTD is not None:
        raise refused_dtd      # a declaration in an encoding the byte check did not cover
    if next(root.iter(f'{{{XINCLUDE_NS}}}*'), None) is not None:
        raise TelemetrySchemaError(name, 'the XTCE file uses XInclude: refused, nothing '
                                   'outside the file is read')
    if etree.QName(root).localname != 'SpaceSystem':
        raise TelemetrySchemaError(name, f'not XTCE: the root element is '
                                   f'<{etree.QName(root).localname}>, expected <SpaceSystem>')
    return data


def refused_entries(data: bytes) -> dict[str, str]:
    """Return container name -> the first entry the sequential reading cannot follow."""
    from lxml import etree
    root = etree.fromstring(data, etree.XMLParser(resolve_entities=False, no_network=True,
                                                  load_dtd=False))
    refused: dict[str, str] = {}
    for container in root.iter('{*}SequenceContainer'):
        name = container.get('name', '?')
        for entry_list in container.iterfind('{*}EntryList'):
            for entry in entry_list:
                why = _entry_problem(entry, etree)
                if why:
                    refused.setdefault(name, why)
    return refused


def _entry_problem(entry: Any, etree: Any) -> str | None:
    if not isinstance(entry.tag, str):
        return None
    tag = etree.QName(entry).localname
    if tag not in _ENTRY_TAGS:
        return f'<{tag}> entries are not supported'
    for child in entry:
        if not isinstance(child.tag, str):
            continue
        inner = etree.QName(child).localname
        if inner != 'LocationInContainerInBits':
            return f'<{inner}> in <{tag}> is not supported'
        fixed = child.find('{*}FixedValue')
        where = child.get('referenceLocation', 'previousEntry')
        if where != 'previousEntry' or fixed is None or (fixed.text or '').strip() != '0':
            return 'an entry at a location other than right after the previous one'
    return None


def load(path: str | os.PathLike) -> Definition:
    """Read an XTCE file safely and parse it with space-packet-parser.

    Raises
    ------
    TelemetrySchemaError
        One line naming the file for anything space-packet-parser cannot take.
    """
    from space_packet_parser import XtcePacketDefinition
    name = os.fspath(path)
    data = screen(name)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', UserWarning)  # a document without the XTCE namespace
        try:
            spp = XtcePacketDefinition.from_xtce(io.BytesIO(data))
        except KeyError as err:
            raise TelemetrySchemaError(name, f'the XTCE refers to {err.args[0]!r}, which it '
                                       'does not define') from None
        except (ValueError, TypeError, AttributeError, NotImplementedError) as err:
            detail = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise TelemetrySchemaError(name, f'not a usable XTCE packet definition: '
                                       f'{detail}') from None
        except Exception as err:  # noqa: BLE001 - the library's own error classes
            detail = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise TelemetrySchemaError(name, f'not a usable XTCE packet definition: '
                                       f'{type(err).__name__}: {detail}') from None
    return Definition(name, spp, refused_entries(data))
