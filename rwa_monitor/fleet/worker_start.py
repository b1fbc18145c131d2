"""What every local fleet worker needs, loaded once by the server the workers fork from.

Imported by the fork server of fleet/cluster.py before any worker exists: Dask's worker,
the modules a step runs and the compiled kernels it calls (from the cache; compiled if
the cache is empty). Each worker is then a fork of a process that has them all.

One thread for the numeric libraries of each worker, as Dask gives the workers it spawns
(``distributed.nanny.pre-spawn-environ``): a forked worker keeps the libraries the server
loaded, so the server sets them before numpy loads. A value in the environment is kept.
"""

import os

for _name in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_name, '1')

import distributed.nanny  # noqa: E402,F401  (the worker process's own start)

from rwa_monitor.core import jit  # noqa: E402
from rwa_monitor.fleet import chain  # noqa: E402,F401

jit.warm()
