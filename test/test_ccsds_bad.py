"""Bad packet files, XTCE files and maps: a one-line error, or a counted, reported behaviour.

Issue 33 item 4: truncated last packet, a length that does not match its container,
unknown APIDs, sequence-count jumps (data gaps by APID), an XTCE that is not XML or refers
to what it does not define, map and XTCE disagreeing both ways, an XTCE asking for DTDs,
entities, remote schemas or XIncludes (refused, nothing fetched), and a 2 GB file read in
bounded memory.
"""

import http.server
import struct
import threading
import tracemalloc

from ccsds_files import cuc, f32, f64, GYRO, HEADER, le32, MAP, packet, pymdb_xtce, WHEEL
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from rwa_monitor.exceptions import ConfigError, TelemetrySchemaError
from rwa_monitor.telemetry import ccsds, ccsds_scan, read_telemetry, telemetry_map, xtce

WHEEL_BYTES = 32


@pytest.fixture(scope='module')
def definition(tmp_path_factory):
    """Return (XTCE, map) of the yamcs-pymdb test definition."""
    folder = tmp_path_factory.mktemp('def')
    (folder / 'map.yaml').write_text(MAP)
    return pymdb_xtce(folder / 'def.xml'), folder / 'map.yaml'


def wheel(count, t=None, speed=100.0, extra=b''):
    t = count / 10 if t is None else t
    return packet(WHEEL, count, [*cuc(t), f64(speed), f32(1e-4), (0, 3), (5, 13), (7, 16),
                                 le32(9)], extra)


def gyro(count):
    t = count / 5 + 0.05
    return packet(GYRO, count, [f64(t), f32(1.0), f32(2.0), f32(3.0)])


def read(path, definition, **kwargs):
    return ccsds.read_packets(path, *definition, **kwargs)


def test_truncated_last_packet_is_dropped_and_counted(tmp_path, definition):
    whole = b''.join(wheel(k) for k in range(10))
    for kept, cut in ((WHEEL_BYTES - 5, 'in the data'), (3, 'in the header')):
        path = tmp_path / 'cut.bin'
        path.write_bytes(whole[:9 * WHEEL_BYTES + kept])
        tele, report = read(path, definition)
        assert len(tele) == 9 and report.truncated_bytes == kept, cut
        assert report.lines() == [f'truncated last packet: its {kept} bytes dropped']


def test_length_not_matching_the_container_is_skipped_and_counted(tmp_path, definition):
    path = tmp_path / 'long.bin'
    path.write_bytes(b''.join(wheel(k, extra=b'\0\0' if k in (2, 5) else b'')
                              for k in range(10)))
    tele, report = read(path, definition)
    assert len(tele) == 8 and report.length_mismatch == {'WheelPacket': 2}
    assert report.decoded['WheelPacket'] == 8
    assert not np.isin(tele.time, [0.2, 0.5]).any()
    assert report.gaps == {}          # the packets were there: no gap


def test_unknown_apids_idle_and_other_versions_are_counted_and_skipped(tmp_path, definition):
    other = packet(555, 0, [(1, 32)])
    idle = packet(2047, 0, [(0, 8)])
    version = bytearray(packet(WHEEL, 0, [(0, 16)]))
    version[0] |= 0x20
    path = tmp_path / 'mixed.bin'
    path.write_bytes(wheel(0) + other * 3 + idle * 2 + bytes(version) + wheel(1))
    tele, report = read(path, definition)
    assert len(tele) == 2
    assert report.unknown_apids == {555: 3} and report.idle == 2 and report.bad_version == 1
    assert report.lines() == [
        '3 packets of APIDs the XTCE does not define skipped (APID 555: 3)',
        '1 packets of a CCSDS version other than 0 skipped']


def test_sequence_count_jumps_are_data_gaps_by_apid(tmp_path, definition):
    packets = [wheel(k) for k in range(20) if k not in (3, 4, 5, 12)]
    packets += [gyro(k) for k in range(10) if k != 7]
    path = tmp_path / 'gaps.bin'
    path.write_bytes(b''.join(packets))
    tele, report = read(path, definition)
    assert report.gaps == {WHEEL: {'gaps': 2, 'missing': 4}, GYRO: {'gaps': 1, 'missing': 1}}
    assert f'APID {WHEEL}: 2 data gaps in the sequence count, 4 packets missing' \
        in report.lines()
    assert len(tele.rows('wheels')) == 16


def test_repeated_packets_are_dropped_but_conflicting_ones_refused(tmp_path, definition):
    path = tmp_path / 'dup.bin'
    path.write_bytes(b''.join([wheel(0), wheel(1), wheel(1), wheel(2)]))
    tele, report = read(path, definition)
    assert len(tele) == 3 and report.duplicates == {'WheelPacket': 1}
    path.write_bytes(b''.join([wheel(0), wheel(1), wheel(2, t=0.1, speed=5.0)]))
    with pytest.raises(TelemetrySchemaError, match='two WheelPacket packets stamped 0.1000061'):
        read(path, definition)


def test_a_file_without_mapped_packets_says_what_it_held(tmp_path, definition):
    path = tmp_path / 'none.bin'
    path.write_bytes(packet(555, 0, [(1, 32)]))
    with pytest.raises(TelemetrySchemaError, match=r'no packet of the mapped containers '
                       r'\(1 packets of APIDs the XTCE does not define'):
        read(path, definition)
    path.write_bytes(b'')
    with pytest.raises(TelemetrySchemaError, match='the file is empty'):
        read(path, definition)


@pytest.mark.parametrize('content, message', [
    (b'time,rw1_speed\n0,1\n', 'not an XML file'),
    (b'\x00\x01\x02binary', 'not an XML file'),
    (b'<?xml version="1.0"?><root/>', r'not XTCE: the root element is <root>'),
    (b'<SpaceSystem xmlns="http://www.omg.org/spec/XTCE/20180204" name="x"/>',
     'not a usable XTCE packet definition'),
])
def test_xtce_that_is_not_xml_or_not_xtce_is_one_line(tmp_path, definition, content, message):
    xml = tmp_path / 'def.xml'
    xml.write_bytes(content)
    (tmp_path / 'p.bin').write_bytes(wheel(0))
    with pytest.raises(TelemetrySchemaError, match=message) as err:
        ccsds.read_packets(tmp_path / 'p.bin', xml, definition[1])
    assert '\n' not in str(err.value) and str(xml) in str(err.value)


def _edited_xtce(tmp_path, definition, old, new):
    text = definition[0].read_text()
    assert old in text
    xml = tmp_path / 'edited.xml'
    xml.write_text(text.replace(old, new, 1))
    return xml


def test_xtce_referring_to_a_parameter_it_does_not_define(tmp_path, definition):
    xml = _edited_xtce(tmp_path, definition, '<ParameterRefEntry parameterRef="HK_MODE"',
                       '<ParameterRefEntry parameterRef="HK_MISSING"')
    (tmp_path / 'p.bin').write_bytes(wheel(0))
    with pytest.raises(TelemetrySchemaError, match="refers to 'HK_MISSING', which it does "
                       'not define'):
        ccsds.read_packets(tmp_path / 'p.bin', xml, definition[1])


@pytest.mark.parametrize('old, new, message', [
    ('rw1_speed: RW1_SPD', 'rw1_speed: RW1_SPDX',
     r"columns: rw1_speed: parameter 'RW1_SPDX' is not in .*did you mean 'RW1_SPD'"),
    ('GyroPacket: GYR_TIME', 'GyroPackt: GYR_TIME',
     r"time: container 'GyroPackt' is not in .*did you mean 'GyroPacket'"),
    ('GyroPacket: GYR_TIME', 'GyroPacket: GYR_TIMES', r"parameter 'GYR_TIMES' is not in"),
    ('GyroPacket: GYR_TIME', 'GyroPacket: SEC',
     "time: GyroPacket: the XTCE container has no parameter 'SEC'"),
    ('rw1_speed: RW1_SPD', 'rw1_speed: HK_MODE',
     r"'HK_MODE' is in no container of time: \(the XTCE has it in HkPacket\)"),
    ('rw1_speed: RW1_SPD', 'rw1_speed: SEC', r"'SEC' is in containers WheelPacket, "
     'StarPacket, RefPacket of time:'),
    ('  q_x: Q_X\n  q_y: Q_Y\n  q_z: Q_Z\n  q_w: Q_W\n', '',
     "container 'StarPacket' carries none of the columns"),
    ('  gyro_y: GYR_Y\n', '', r'columns: missing gyro_y \(a group is all or nothing'),
    ('epoch_utc: 2026-01-01T00:00:00Z', 'epoch_utc: tomorrow', 'epoch_utc: expected'),
    ('subsecond_scale: 65536', 'subsecond_scale: 0.5', 'subsecond_scale must be an integer'),
    ('columns:', 'colums:', "unknown key 'colums'"),
])
def test_map_and_xtce_disagreeing_either_way_is_one_line(tmp_path, definition, old, new,
                                                         message):
    text = definition[1].read_text()
    assert old in text
    yml = tmp_path / 'map.yaml'
    yml.write_text(text.replace(old, new, 1))
    (tmp_path / 'p.bin').write_bytes(wheel(0))
    with pytest.raises(ConfigError, match=message) as err:
        ccsds.read_packets(tmp_path / 'p.bin', definition[0], yml)
    assert '\n' not in str(err.value) and str(yml) in str(err.value)


class _Counter(http.server.BaseHTTPRequestHandler):
    requests: list[str] = []

    def do_GET(self):  # noqa: N802 - the http.server hook
        type(self).requests.append(self.path)
        self.send_response(200)
        self.end_headers()
        self.wfile.write(b'<!ENTITY x "fetched">')

    def log_message(self, *args):
        pass


@pytest.fixture()
def server():
    _Counter.requests = []
    httpd = http.server.ThreadingHTTPServer(('127.0.0.1', 0), _Counter)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f'http://127.0.0.1:{httpd.server_address[1]}'
    httpd.shutdown()
    httpd.server_close()


def _document(text, preamble='', root_attributes=''):
    """Return the test XTCE with ``preamble`` before its root and attributes on it."""
    return text.replace('<SpaceSystem ', f'{preamble}<SpaceSystem {root_attributes} ', 1)


@pytest.mark.parametrize('kind', ['billion_laughs', 'external_entity', 'file_entity',
                                  'external_dtd', 'xinclude'])
def test_dtds_entities_and_xincludes_are_refused_and_nothing_is_fetched(
        tmp_path, definition, server, kind):
    text = definition[0].read_text()
    laughs = ''.join(f'<!ENTITY l{i} "{f"&l{i - 1};" * 10}">' for i in range(1, 10))
    preamble, attributes = {
        'billion_laughs': (f'<!DOCTYPE SpaceSystem [<!ENTITY l0 "lol">{laughs}]>\n', ''),
        'external_entity': (f'<!DOCTYPE SpaceSystem [<!ENTITY x SYSTEM "{server}/e">]>\n', ''),
        'file_entity': ('<!DOCTYPE SpaceSystem [<!ENTITY x SYSTEM "file:///etc/hostname">]>\n',
                        ''),
        'external_dtd': (f'<!DOCTYPE SpaceSystem SYSTEM "{server}/x.dtd">\n', ''),
        'xinclude': ('', 'xmlns:xi="http://www.w3.org/2001/XInclude"'),
    }[kind]
    document = _document(text, preamble, attributes)
    use = {'billion_laughs': '&l9;', 'external_entity': '&x;', 'file_entity': '&x;',
           'xinclude': f'<xi:include href="{server}/i.xml"/>'}.get(kind)
    if use:
        document = document.replace('<TelemetryMetaData>', f'<LongDescription>{use}'
                                    '</LongDescription><TelemetryMetaData>', 1)
    xml = tmp_path / 'evil.xml'
    xml.write_text(document)
    (tmp_path / 'p.bin').write_bytes(wheel(0))
    with pytest.raises(TelemetrySchemaError, match='refused') as err:
        ccsds.read_packets(tmp_path / 'p.bin', xml, definition[1])
    assert '\n' not in str(err.value)
    assert _Counter.requests == []


def test_a_remote_schema_location_is_never_fetched(tmp_path, definition, server):
    text = definition[0].read_text()
    xml = tmp_path / 'located.xml'
    xml.write_text(text.replace('https://www.omg.org/spec/XTCE/20180204/SpaceSystem.xsd',
                                f'{server}/SpaceSystem.xsd'))
    assert f'{server}/SpaceSystem.xsd' in xml.read_text()
    (tmp_path / 'p.bin').write_bytes(wheel(0) + wheel(1))
    tele, _ = ccsds.read_packets(tmp_path / 'p.bin', xml, definition[1])
    assert len(tele) == 2 and _Counter.requests == []


def test_a_container_neither_decoder_reads_is_counted(tmp_path):
    """yamcs-pymdb's leading-size string names a Yamcs-only size reference."""
    import yamcs.pymdb as y
    system = y.System('S')
    header = [y.IntegerParameter(system, n, signed=False, encoding=y.IntegerEncoding(bits=b))
              for n, b in HEADER]
    root = y.Container(system, 'CCSDSPacket', abstract=True,
                       entries=[y.ParameterEntry(p) for p in header])
    entries = [y.FloatParameter(system, 'T', bits=64, encoding=y.FloatEncoding(bits=64)),
               y.StringParameter(system, 'LABEL', encoding=y.StringEncoding(
                   length_bits=8, termination=None)),
               y.FloatParameter(system, 'V', bits=64, encoding=y.FloatEncoding(bits=64))]
    y.Container(system, 'P', base=root, condition=y.eq(header[3], 7),
                entries=[y.ParameterEntry(p) for p in entries])
    with open(tmp_path / 's.xml', 'w') as handle:
        system.dump(handle)
    (tmp_path / 's.yaml').write_text('time: {P: T}\ncolumns: {aux_v: V}\n')
    (tmp_path / 's.bin').write_bytes(packet(7, 0, [f64(1.0), (2, 8)], b'ab' + struct.pack(
        '>d', 3.0)))
    with pytest.raises(TelemetrySchemaError, match=r'P packets the XTCE decoder could not '
                       r"read skipped: 1 \(KeyError: '_yamcs_ignore'\)"):
        ccsds.read_packets(tmp_path / 's.bin', tmp_path / 's.xml', tmp_path / 's.yaml')


@pytest.mark.slow
def test_a_2_gib_file_is_read_in_bounded_memory(tmp_path, definition):
    """A sparse file: wheel packets, 2 GiB of zeros (7-byte packets of APID 0), packets."""
    head = b''.join(wheel(k) for k in range(50))
    tail = b''.join(wheel(k) for k in range(50, 100))
    zeros = (2 * 1024 ** 3 // 7) * 7
    path = tmp_path / 'big.bin'
    with open(path, 'wb') as handle:
        handle.write(head)
        handle.seek(len(head) + zeros)
        handle.write(tail)
    assert path.stat().st_size > 2 * 1024 ** 3
    xml, tmap = xtce.load(definition[0]), telemetry_map.read_map(definition[1])
    columns_of = telemetry_map.check(tmap, xml)
    tracemalloc.start()
    try:
        decoded, report = ccsds.decode_file(path, xml, tmap, columns_of,
                                            chunk_bytes=4 * 1024 * 1024)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        path.unlink()
    assert len(decoded['WheelPacket']['RW1_SPD']) == 100
    assert report.unknown_apids == {0: zeros // 7}
    assert report.gaps == {} and report.truncated_bytes == 0
    # The buffer (chunk + one packet), a batch of offsets, lengths and header words, 1 MiB
    # for the rest: about 11 MiB.
    bound = 4 * 1024 * 1024 + ccsds_scan.MAX_PACKET + 3 * 8 * ccsds_scan.BATCH + 2**20
    assert peak < bound, (peak, bound)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=400), cut=st.integers(0, 2000))
def test_any_bytes_give_a_record_or_one_line(tmp_path, definition, data, cut):
    valid = b''.join(wheel(k) for k in range(20)) + b''.join(gyro(k) for k in range(10))
    path = tmp_path / 'fuzz.bin'
    path.write_bytes(valid[:cut] + data + valid[cut:])
    try:
        tele = read_telemetry(path, xtce=definition[0], telemetry_map=definition[1])
    except TelemetrySchemaError as err:
        assert '\n' not in str(err)
    else:
        assert np.all(np.diff(tele.time) > 0)
