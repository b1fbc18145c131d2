"""Least squares on a growing set of columns, scored on training and held-out rows."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RCOND = 1e-10


BLOCKS = 60
TEST_EVERY = 3
VALIDATION_EVERY = 6


def _blocks(n: int, blocks: int = BLOCKS) -> np.ndarray:
    return np.minimum(np.arange(n) * blocks // max(n, 1), blocks - 1)


def held_out_mask(n: int, blocks: int = BLOCKS, every: int = TEST_EVERY) -> np.ndarray:
    """Return the held-out test rows: every ``every``-th of ``blocks`` contiguous time blocks.

    Interleaved blocks (not the last third) so that a slow effect (drift, temperature)
    is seen over its whole range on both sides; contiguous blocks so that neighbouring,
    correlated samples rarely sit on both sides. These rows are never used to fit or to
    choose anything: their RMSE is the held-out result reported.
    """
    return _blocks(n, blocks) % every == every - 1


def validation_mask(n: int, blocks: int = BLOCKS, every: int = VALIDATION_EVERY
                    ) -> np.ndarray:
    """Return the validation rows: every ``every``-th block, carved from the training part.

    The selection's decisions (an effect's confirmation on rows it was not fitted on,
    the choice among significant effects and among named sets) use these rows, never the
    held-out test rows (:func:`held_out_mask`); blocks 0, 6, 12, ... (none of them a test
    block), so that with the defaults half of the rows are fitted, a sixth validate and
    a third test.
    """
    block = _blocks(n, blocks)
    return (block % every == 0) & ~held_out_mask(n, blocks)


@dataclass(frozen=True)
class Split:
    """Rows of a record: validation (selection decisions) and test (reported only)."""

    validation: np.ndarray
    test: np.ndarray

    @property
    def train(self) -> np.ndarray:
        """Return the rows the weights are fitted on."""
        return ~(self.validation | self.test)

    @property
    def decision(self) -> np.ndarray:
        """Return the rows any decision may look at (all but the test rows)."""
        return ~self.test


def split_rows(n: int) -> Split:
    """Return the fixed split of n rows: training, validation and held-out test blocks."""
    return Split(validation_mask(n), held_out_mask(n))


@dataclass
class Fit:
    """A least-squares fit: coefficients, rank, and sums of squares on the three row sets.

    Fitted on the training rows; ``validation`` rows serve the selection's decisions,
    ``test`` rows (the held-out result) only the report.
    """

    coef: np.ndarray
    rank: int
    rss_train: float
    rss_validation: float
    rss_test: float
    n_train: int
    n_validation: int
    n_test: int

    @property
    def rmse_train(self) -> float:
        """Return the in-sample root-mean-square residual."""
        return float(np.sqrt(self.rss_train / self.n_train))

    @property
    def rmse_validation(self) -> float:
        """Return the root-mean-square residual on the validation rows."""
        return float(np.sqrt(self.rss_validation / max(self.n_validation, 1)))

    @property
    def rmse_test(self) -> float:
        """Return the held-out (test) root-mean-square residual."""
        return float(np.sqrt(self.rss_test / max(self.n_test, 1)))


class Design:
    """The columns of the current model; scores candidate columns without refitting all.

    The Gram matrix of the current columns on the training rows is kept, so a candidate
    of k columns costs O(n p k) rather than O(n (p + k)^2). The thin products are einsum
    loops, not threaded BLAS calls: on a loaded machine a threaded product of an (n, 1)
    column cost 30-90 ms (measured), the loop well under one.
    """

    def __init__(self, y: np.ndarray, columns: np.ndarray, split: Split) -> None:
        self.y = np.asarray(y, dtype=float)
        self.split = split
        self.train = split.train
        self._rows = {'validation': split.validation, 'test': split.test}
        self.X = np.empty((len(self.y), 0))
        self._xt = np.empty((int(np.sum(self.train)), 0))
        self._xo = {k: np.empty((int(np.sum(m)), 0)) for k, m in self._rows.items()}
        self._yo = {k: self.y[m] for k, m in self._rows.items()}
        self._yt = self.y[self.train]
        self._yy = float(self._yt @ self._yt)
        self._n_train = len(self._yt)
        self._gram = np.empty((0, 0))
        self._xy = np.empty(0)
        self.add(columns)

    def add(self, columns: np.ndarray) -> None:
        """Append columns to the model."""
        columns = np.asarray(columns, dtype=float).reshape(len(self.y), -1)
        self._gram, self._xy = self._extended(columns)
        self.X = np.hstack([self.X, columns])
        self._xt = np.ascontiguousarray(self.X[self.train])
        self._xo = {k: np.ascontiguousarray(self.X[m]) for k, m in self._rows.items()}

    def _extended(self, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ct = columns[self.train]
        xc = np.einsum('ij,ik->jk', self._xt, ct)
        gram = np.block([[self._gram, xc], [xc.T, np.einsum('ij,ik->jk', ct, ct)]])
        return gram, np.concatenate([self._xy, np.einsum('ij,i->j', ct, self._yt)])

    def fit(self, columns: np.ndarray | None = None) -> Fit:
        """Return the fit of the current columns, plus ``columns`` if given."""
        p = self.X.shape[1]
        if columns is None:
            gram, xy = self._gram, self._xy
        else:
            columns = np.asarray(columns, dtype=float).reshape(len(self.y), -1)
            gram, xy = self._extended(columns)
        diag = np.sqrt(np.maximum(np.diag(gram), 0.0))
        scale = np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0)
        z, _, rank, _ = np.linalg.lstsq(gram * scale[:, None] * scale[None, :], xy * scale,
                                        rcond=RCOND)
        coef = z * scale
        rss_train = max(self._yy - 2.0 * coef @ xy + coef @ gram @ coef, 0.0)
        rss = {}
        for key, rows in self._rows.items():
            resid = self._yo[key] - np.einsum('ij,j->i', self._xo[key], coef[:p])
            if columns is not None:
                resid -= np.einsum('ij,j->i', columns[rows], coef[p:])
            rss[key] = float(np.einsum('i,i->', resid, resid))
        return Fit(coef=coef, rank=int(rank), rss_train=float(rss_train),
                   rss_validation=rss['validation'], rss_test=rss['test'],
                   n_train=self._n_train, n_validation=len(self._yo['validation']),
                   n_test=len(self._yo['test']))

    def residual(self, fit: Fit) -> np.ndarray:
        """Return y minus the model of ``fit`` (current columns) on every row."""
        return self.y - self.X @ fit.coef
