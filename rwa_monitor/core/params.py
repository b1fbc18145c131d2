"""Validation of keyword parameters: every failure names the parameter and its range."""

from __future__ import annotations

import math
import numbers

# The one spelling of an automatic value, in Python, YAML and ROS parameters alike.
AUTO = 'auto'


def _interval(low: float, high: float, low_open: bool, high_open: bool) -> str:
    return f'{"(" if low_open else "["}{low:g}, {high:g}{")" if high_open else "]"}'


def check_real(name: str, value: float, low: float = -math.inf, high: float = math.inf,
               low_open: bool = False, high_open: bool = False) -> float:
    """Return ``value`` as a float if it is finite and in the interval, else ValueError.

    The interval is ``[low, high]``; ``low_open``/``high_open`` exclude the end points.
    """
    interval = _interval(low, high, low_open, high_open)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f'{name} must be a real number in {interval}, got {value!r}')
    x = float(value)
    below = x <= low if low_open else x < low
    above = x >= high if high_open else x > high
    if not math.isfinite(x) or below or above:
        raise ValueError(f'{name} must be a finite number in {interval}, got {value!r}')
    return x


def check_int(name: str, value: int, low: int | None = None, high: int | None = None) -> int:
    """Return ``value`` as an int if it is an integer in ``[low, high]``, else ValueError."""
    interval = f'[{"-inf" if low is None else low}, {"inf" if high is None else high}]'
    if (isinstance(value, bool) or not isinstance(value, numbers.Integral)
            or (low is not None and value < low) or (high is not None and value > high)):
        raise ValueError(f'{name} must be an integer in {interval}, got {value!r}')
    return int(value)


def check_choice(name: str, value: str, choices: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of ``choices``, else ValueError listing them."""
    if value not in choices:
        raise ValueError(f'{name} must be one of {", ".join(choices)}; got {value!r}')
    return value
