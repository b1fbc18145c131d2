"""Linear-in-parameters friction models and least squares (llr-realtime paper, eq. (1)-(3)).

Sign convention (eq. (1)): the measured friction torque is ``f = h x + e`` with the row
``h = -[sign(w), w]`` and ``x = [f_c, f_v] >= 0`` for friction that opposes the motion.
The simulator writes ``friction = -f_c * sign(w) - f_v * w + noise``: the same thing.
``sign(0) = 0``: a sample taken with the wheel at rest carries no dry-friction
information (and, with ``w = 0``, no viscous information either: its row is zero).

A :class:`RegressorSet` is any such model: named columns, each a callable
``(speed, time, aux) -> array`` evaluated on arrays (``aux`` maps auxiliary channel names to
arrays of the same length, or is None). The first two columns are always ``dry`` and
``viscous``, with the sign of eq. (1), so that ``x[0]`` and ``x[1]`` keep their meaning when
columns are added (e.g. ``-sign(w) |w|^a`` or an auxiliary channel).
"""

from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np

Column = Callable[[np.ndarray, 'np.ndarray | None', 'Mapping[str, np.ndarray] | None'],
                  np.ndarray]


def dry_column(speed, time=None, aux=None) -> np.ndarray:
    """Return ``-sign(w)`` (the dry-friction regressor of eq. (1); 0 at rest)."""
    return -np.sign(speed)


def viscous_column(speed, time=None, aux=None) -> np.ndarray:
    """Return ``-w`` (the viscous-friction regressor of eq. (1))."""
    return -np.asarray(speed, dtype=float)


class RegressorSet:
    """Named regressor columns ``h(speed, time, aux)`` of a linear friction model.

    ``names[0] == 'dry'`` and ``names[1] == 'viscous'`` (eq. (1) columns, paper sign);
    further columns are free. ``matrix`` stacks the columns into the ``(n, p)`` matrix whose
    rows are the ``h_l`` of eq. (1).
    """

    def __init__(self, names: Sequence[str], columns: Sequence[Column]):
        names = tuple(str(n) for n in names)
        columns = tuple(columns)
        if len(names) < 2 or names[0] != 'dry' or names[1] != 'viscous':
            raise ValueError(f"names must start with 'dry', 'viscous'; got {names!r}")
        if len(set(names)) != len(names):
            raise ValueError(f'names must be unique; got {names!r}')
        if len(columns) != len(names):
            raise ValueError(f'columns must have one callable per name ({len(names)}), '
                             f'got {len(columns)}')
        if not all(callable(c) for c in columns):
            raise ValueError('columns must be callables (speed, time, aux) -> array')
        self._names = names
        self._columns = columns

    @property
    def names(self) -> tuple[str, ...]:
        """Column names, ``('dry', 'viscous', ...)``."""
        return self._names

    @property
    def columns(self) -> tuple[Column, ...]:
        """Column callables, in the order of :attr:`names`."""
        return self._columns

    @property
    def p(self) -> int:
        """Number of columns (parameters)."""
        return len(self._names)

    @property
    def is_coulomb_viscous(self) -> bool:
        """Return True if this is exactly the paper's two-column model."""
        return self._columns == (dry_column, viscous_column)

    def matrix(self, speed, time=None, aux: Mapping[str, np.ndarray] | None = None
               ) -> np.ndarray:
        """Stack the columns into the regressor matrix, one row ``h_l`` (eq. (1)) per sample."""
        speed = np.asarray(speed, dtype=float).reshape(-1)
        n = speed.size
        out = np.empty((n, self.p))
        for j, col in enumerate(self._columns):
            out[:, j] = np.broadcast_to(np.asarray(col(speed, time, aux), dtype=float), (n,))
        return out

    def __repr__(self) -> str:
        return f'RegressorSet({self._names!r})'


def coulomb_viscous() -> RegressorSet:
    """Return the paper's model (eq. (1)): ``h = -[sign(w), w]``, ``x = [f_c, f_v]``."""
    return RegressorSet(('dry', 'viscous'), (dry_column, viscous_column))


def normal_equations(h: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(Pi, q) = (sum h_l^T h_l, sum h_l^T f_l)`` (eq. (2) notation)."""
    h = np.asarray(h, dtype=float)
    f = np.asarray(f, dtype=float).reshape(-1)
    return h.T @ h, h.T @ f


def least_squares(h: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Return ``x = Pi^-1 q``, the least-squares estimate of eq. (2).

    Solved with an orthogonal factorisation of ``h`` (``numpy.linalg.lstsq``) rather than by
    inverting ``Pi``: same estimate, better conditioned. Rank-deficient ``h`` gives the
    minimum-norm solution.
    """
    x, *_ = np.linalg.lstsq(np.asarray(h, dtype=float), np.asarray(f, dtype=float),
                            rcond=None)
    return x


class RecursiveLeastSquares:
    """Recursive least squares with the Sherman-Morrison update of eq. (3).

    Starts from ``Pi = prior * I`` (a small ridge ``prior`` makes ``Pi`` invertible before
    ``p`` independent rows arrived; the estimate converges to eq. (2) as data accumulate;
    ``prior = 0`` is allowed once :meth:`initialise` was called with a full-rank batch).
    """

    def __init__(self, p: int, prior: float = 1e-9):
        if p < 1:
            raise ValueError(f'p must be an integer in [1, inf], got {p!r}')
        if not prior > 0.0:
            raise ValueError(f'prior must be a number in (0, inf), got {prior!r}')
        self._pinv = np.eye(p) / prior
        self._q = np.zeros(p)
        self._n = 0

    def initialise(self, h: np.ndarray, f: np.ndarray) -> None:
        """Replace the state by the exact normal equations of a full-rank batch."""
        pi, q = normal_equations(h, f)
        self._pinv = np.linalg.inv(pi)
        self._q = q
        self._n = int(np.asarray(f).size)

    def add(self, h_row: np.ndarray, f: float) -> None:
        """Add one sample: eq. (3) for ``Pi^-1`` and ``q += h^T f``."""
        h = np.asarray(h_row, dtype=float).reshape(-1)
        ph = self._pinv @ h
        self._pinv -= np.outer(ph, ph) / (1.0 + h @ ph)
        self._q += h * float(f)
        self._n += 1

    @property
    def estimate(self) -> np.ndarray:
        """Current ``x = Pi^-1 q``."""
        return self._pinv @ self._q

    @property
    def inverse(self) -> np.ndarray:
        """Current ``Pi^-1``."""
        return self._pinv.copy()

    @property
    def n_samples(self) -> int:
        """Number of samples added."""
        return self._n
