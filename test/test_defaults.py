"""Defaults with one home: each detector's keyword defaults are its schema's, value for value.

core/schema.py is the home; config/rwa_monitor.yaml and docs/parameters.md are checked
against it by test/test_schema.py (the shipped values and the generated tables). Here the
third copy: the defaults a detector class shows (``inspect.signature``) must be the values
the schema's defaults turn into through the same keyword mapping the nodes and pipelines
use, for every keyword that is a parameter, and every parameter must be a keyword.
"""

import inspect

import pytest

import rwa_monitor
from rwa_monitor.core.gyro_diagnosis import gyro_diagnosis_kwargs
from rwa_monitor.core.gyro_residual import ResidualAxis
from rwa_monitor.core.schema import FSS, LLR, llr_kwargs, VSADC, vsadc_kwargs
from rwa_monitor.core.vsadc import VsadcAxis, VsadcDetector

# Keywords that are not parameters: the wheel id, the regressor objects, the calibration
# contents and the classifier are data given by the caller.
NOT_PARAMETERS = {'component', 'regressors', 'calibration', 'classifier'}
FSS_KEYWORDS = ('window_length', 'window_period') + tuple(
    n for n in FSS.names(('all',)) if n != 'model')

SCHEMA_KWARGS = {
    'LLRDetector': lambda: llr_kwargs(LLR.validate({})),
    'VsadcDetector': lambda: vsadc_kwargs(VSADC.validate({})),
    'GyroDiagnosis': lambda: gyro_diagnosis_kwargs(VSADC.validate({})),
    'FssDiagnoser': lambda: {n: FSS[n].default for n in FSS_KEYWORDS},
}


def _defaults(cls):
    return {name: p.default for name, p in inspect.signature(cls).parameters.items()
            if name not in NOT_PARAMETERS}


def _typed(mapping):
    """Return the values with their types: 1 and 1.0, or True and 1, are not the same."""
    return {k: (type(v).__name__, v) for k, v in mapping.items()}


@pytest.mark.parametrize('name', sorted(SCHEMA_KWARGS))
def test_class_defaults_are_the_schema_defaults(name):
    cls = getattr(rwa_monitor, name)
    assert _typed(_defaults(cls)) == _typed(SCHEMA_KWARGS[name]())


def test_every_exported_detector_is_checked():
    from test_protocol import FAMILIES
    assert set(SCHEMA_KWARGS) == set(FAMILIES)


def test_axis_defaults_are_the_detector_defaults():
    detector = _defaults(VsadcDetector)
    assert _typed(_defaults(VsadcAxis)) == _typed(
        {k: detector[k] for k in _defaults(VsadcAxis)})
    residual = SCHEMA_KWARGS['GyroDiagnosis']()
    axis = ResidualAxis()
    assert {k: getattr(axis, k) for k in residual if hasattr(axis, k) and k != 'axes'} == \
        {k: v for k, v in residual.items() if hasattr(axis, k) and k != 'axes'}


def test_schema_and_class_give_the_same_detector():
    # The seam of issue 25: window 300 through the schema and as a keyword.
    through_schema = VsadcDetector(**vsadc_kwargs(VSADC.validate({'window': 300})))
    direct = VsadcDetector(window=300)
    assert through_schema.channels[0].sigma_window == direct.channels[0].sigma_window == 300
    assert through_schema.params == direct.params
