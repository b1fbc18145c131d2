"""FSS classifier files: read and write the JSON of a trained WindowClassifier.

The classifier itself (core/fss/classify.py) is arrays in, booleans out; its files live
here, above the core. :data:`DEFAULT_MODEL` is the model shipped with the package.
"""

from __future__ import annotations

import json
import math
import os
import pathlib

from rwa_monitor.core.fss.classify import noise_ratio_bound, WindowClassifier
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.atomic import write_text_atomic

DEFAULT_MODEL = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fss_model.json'


def load_model(path: str | os.PathLike | None = None) -> WindowClassifier:
    """Return the classifier at ``path`` or the shipped default model.

    FileNotFoundError names a missing file; ConfigError (a ValueError) a file that is not
    a usable model: not UTF-8 JSON, not a model, or one whose decision on a plain window
    fails or is not finite (a damaged file is refused here, not in the middle of a run).

    Parameters
    ----------
    path : str or path, optional
        A model written by ``rwa-monitor fss train``; None: the shipped model.

    Returns
    -------
    WindowClassifier
        The classifier of the window diagnoser (core/fss/classify.py).

    Examples
    --------
    >>> model = load_model()
    >>> type(model).__name__
    'WindowClassifier'
    >>> load_model('no_such_model.json')
    Traceback (most recent call last):
    ...
    FileNotFoundError: FSS model not found: no_such_model.json (train one with \
`rwa-monitor fss train DATASET -o MODEL`)
    """
    path = DEFAULT_MODEL if path is None else pathlib.Path(path)
    if not path.is_file():
        raise FileNotFoundError(f'FSS model not found: {path} (train one with '
                                f'`rwa-monitor fss train DATASET -o MODEL`)')
    try:
        spec = json.loads(path.read_text(encoding='utf-8'))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as err:
        raise ConfigError(f'{path}: not JSON: {err}') from None
    if not isinstance(spec, dict):
        raise ConfigError(f'{path}: not an FSS model (expected a JSON object)')
    try:
        model = WindowClassifier(spec)
        systems = sum(1 for name in model.names if str(name).startswith('fss'))
        window = {'base_dry': 1.0, 'viscous': 1.0, 'levels': [[1.0, 2.0]] * systems}
        values = list(model.decision(window).values())
        noise_ratio_bound(spec.get('noise_ratio'))
    except (ValueError, TypeError, KeyError, IndexError, AttributeError) as err:
        raise ConfigError(f'{path}: not a usable FSS model: {err!r}') from None
    if not all(isinstance(v, float) and math.isfinite(v) for v in values):
        raise ConfigError(f'{path}: not a usable FSS model: non-finite decision values')
    return model


def save_model(classifier: WindowClassifier, path: str | os.PathLike) -> None:
    """Write a classifier as JSON (atomically)."""
    write_text_atomic(path, json.dumps(classifier.spec, indent=1) + '\n')
