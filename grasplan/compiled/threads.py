"""How many threads NumPy's BLAS (and OpenMP) may start in a grasplan process: one, unless the
environment says otherwise. A command's and a planner's matrices are small; extra BLAS threads
only spin after each call and take cores from the work (or from the other planners of a service).
Imports nothing heavy: it must run before NumPy loads."""
from __future__ import annotations

import os
import sys
from collections.abc import Mapping, MutableMapping

#: the thread-count variables of the BLAS builds NumPy may load, each set to 1
ONE_BLAS_THREAD: Mapping[str, str] = {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: the same and OpenMP's: a service's planner processes, where the planners are the parallelism
ONE_THREAD: Mapping[str, str] = {**ONE_BLAS_THREAD, "OMP_NUM_THREADS": "1"}


def one_thread(env: MutableMapping[str, str], names: Mapping[str, str] = ONE_THREAD) -> MutableMapping[str, str]:
    """``env`` with each variable of ``names`` it does not set added (a value given wins)."""
    for k, v in names.items():
        env.setdefault(k, v)
    return env


def one_blas_thread_here() -> None:
    """:data:`ONE_BLAS_THREAD` in this process's environment, unless set, when NumPy is not loaded
    yet (after that its BLAS has started its threads; OpenMP users such as CoACD keep theirs)."""
    if "numpy" not in sys.modules:
        one_thread(os.environ, ONE_BLAS_THREAD)
