"""BLAS thread control for the filter (``one_blas_thread``).

The filter's BLAS calls are small: a second thread helps little and, when the other core is
busy, OpenBLAS's spinning threads make a run many times slower (a Victoria Park run took
54 s instead of 4 s), so a run uses one thread whatever OMP_NUM_THREADS says.
"""
from __future__ import annotations

import contextlib
import ctypes

__all__ = ["one_blas_thread", "openblas_thread_controls"]


def openblas_thread_controls() -> list:
    """(set, get) thread-count functions of every OpenBLAS loaded in this process (NumPy
    and SciPy each bundle one), found through /proc/self/maps; empty elsewhere."""
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh
                     if "openblas" in line.lower() and ".so" in line.rsplit("/", 1)[-1]}
    except OSError:
        return []
    out = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix in ("scipy_openblas", "openblas"):
            for suffix in ("64_", ""):
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and put is not None:
                    get.restype, put.argtypes = ctypes.c_int, [ctypes.c_int]
                    out.append((put, get))
    return out



@contextlib.contextmanager
def one_blas_thread():
    """Run the enclosed code with single-threaded BLAS, then restore the thread counts.

    The filter's BLAS calls are small (rank-2m updates, n <= ~700): a second thread
    helps little and, when the other core is busy, OpenBLAS's spinning threads make a
    Victoria Park run many times slower (measured: 54 s instead of 4 s). ``run`` uses this
    whatever OMP_NUM_THREADS says. Uses threadpoolctl if installed, else the OpenBLAS
    libraries' own setters (Linux); elsewhere it changes nothing."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
        return
    saved = []
    try:
        for put, get in openblas_thread_controls():
            saved.append((put, get()))
            put(1)
        yield
    finally:
        for put, n in saved:
            put(n)
