"""numpy's own BLAS, callable from the compiled learner (kernels.py).

Eq. 2's weighted sum over the fired rules and Eq. 9's contraction with P are dot products, and numpy hands them to
its BLAS (OpenBLAS, the scipy-openblas64 build its wheels ship), whose kernels add the products in their own order
with fused multiply-adds: a plain loop differs from them in the last bit in most cases. The runs pinned by
tests/test_golden.py were learned with numpy, so the compiled learner calls the very functions numpy calls, with the
arguments numpy passes them (kernels.q_values, q_value, expected_values).

numba resolves an external function by its symbol name when it links compiled code (also code loaded from its
cache), so numpy's BLAS library, which Python loaded privately as a dependency of numpy, is made global here.
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import numpy as np
from numba import types

# ILP64 cblas, as numpy's wheels (scipy-openblas64: "scipy_" prefix, "64_" suffix) and ILP64 OpenBLAS builds name it
_NAMES = ("scipy_cblas_{}64_", "cblas_{}64_")
ROW_MAJOR, COL_MAJOR, TRANS = 101, 102, 112  # CBLAS_ORDER and CBLAS_TRANSPOSE values


def _blas_libraries() -> list[str]:
    """Files of the BLAS libraries this process has loaded (Linux), else those numpy's wheel ships."""
    if os.path.exists("/proc/self/maps"):
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "blas" in line.rsplit("/", 1)[-1].lower()}
    else:  # numpy.libs next to numpy (Linux and Windows wheels), numpy/.dylibs (macOS)
        here = Path(np.__file__).parent
        paths = {str(p) for d in (here.parent / "numpy.libs", here / ".dylibs") for p in d.glob("*blas*")}
    return sorted(p for p in paths if os.path.isfile(p))


def _numpy_cblas() -> str:
    """The name pattern of the cblas functions in the BLAS library numpy loaded, after making its symbols global."""
    for path in _blas_libraries():
        try:
            lib = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | ctypes.RTLD_GLOBAL)  # the copy numpy loaded, no other
        except OSError:
            continue
        for pattern in _NAMES:
            if hasattr(lib, pattern.format("dgemv")) and hasattr(lib, pattern.format("ddot")):
                return pattern
    raise ImportError(
        "the learner calls numpy's BLAS from compiled code, but no loaded library exports an ILP64 cblas "
        f"({', '.join(p.format('dgemv') for p in _NAMES)}); numpy's wheels ship one (scipy-openblas64)"
    )


_PATTERN = _numpy_cblas()
_f64p, _i64, _i32 = types.CPointer(types.float64), types.int64, types.int32
#: y = alpha op(A) x + beta y: (order, trans, M, N, alpha, A, lda, x, incx, beta, y, incy)
dgemv = types.ExternalFunction(
    _PATTERN.format("dgemv"),
    types.void(_i32, _i32, _i64, _i64, types.float64, _f64p, _i64, _f64p, _i64, types.float64, _f64p, _i64),
)
#: sum_i x_i y_i: (n, x, incx, y, incy)
ddot = types.ExternalFunction(_PATTERN.format("ddot"), types.float64(_i64, _f64p, _i64, _f64p, _i64))
