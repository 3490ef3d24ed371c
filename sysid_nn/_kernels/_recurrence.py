"""Pieces shared by the recurrent kernels: rows, Jacobian modes, normal equations.

The kernels produce one Jacobian row ``d yhat_k(t) / d w`` at a time. What
happens to it depends on the Jacobian mode:

* ``NO_JAC``: none is computed;
* ``FULL_JAC``: every row is kept in an ``(n_residuals, n_w)`` matrix;
* ``NORMAL``: only the rows the recurrence still needs are kept (the TDL's
  last ``output_lags`` steps in a ring, the ISSM's previous state
  sensitivities), and each row with its error ``yhat_k(t) - y_k(t)`` goes to
  :func:`add_row`, which collects a block of rows and folds it into
  ``JtJ += Jb' Jb`` and ``Jtr += Jb' rb`` with one BLAS call per block.
  Memory is then ``O(block * n_w + n_w**2)`` whatever the record length, and
  the products run at matrix-multiply speed.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import get_cython_function_address, intrinsic

NO_JAC = 0
FULL_JAC = 1
NORMAL = 2
#: Rows collected before each fold into the normal equations.
BLOCK = 256


@njit(cache=True)
def new_block(n_w, jac):
    """Scratch block ``(rows, errors)`` for :func:`add_row` (empty unless NORMAL)."""
    n = BLOCK if jac == NORMAL else 0
    return np.empty((n, n_w)), np.empty(n)


def _blas_syrk() -> int:
    """Address of BLAS ``dsyrk`` (symmetric rank-k update), SciPy's copy.

    The kernels take it as a plain integer and call it through
    :func:`_call_address`: a ctypes function as argument would cost
    microseconds of typing at every kernel call, and as a global it would
    stop numba from caching the kernels. ``J'J`` by ``dsyrk`` takes half the
    work of a general matrix product.
    """
    return get_cython_function_address("scipy.linalg.cython_blas", "dsyrk")


#: The ``syrk`` argument of the kernels.
SYRK = _blas_syrk()


@intrinsic
def _call_address(typingctx, address, args):
    """Call the C function ``void f(void *, ...)`` at ``address`` with ``args``.

    ``args`` is a tuple of integer addresses (``array.ctypes.data``).
    """
    sig = types.void(address, args)

    def codegen(context, builder, signature, llvm_args):
        pointer = ir.IntType(8).as_pointer()
        values = cgutils.unpack_tuple(builder, llvm_args[1])
        fnty = ir.FunctionType(ir.VoidType(), [pointer] * len(values))
        fn = builder.inttoptr(llvm_args[0], fnty.as_pointer())
        builder.call(fn, [builder.inttoptr(v, pointer) for v in values])
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True)
def _flush(Jb, rb, m, JtJ, Jtr, syrk):
    """Fold the first ``m`` rows of the block into ``JtJ`` (lower) and ``Jtr``."""
    if m == 0:
        return
    # Fortran dsyrk on the block seen as a column-major (n_w, m) matrix B:
    # C += B B', whose upper triangle is the lower one of C-ordered ``JtJ``.
    flags = np.array([ord("U"), ord("N")], dtype=np.uint8)
    ints = np.array([Jb.shape[1], m, Jb.shape[1], JtJ.shape[0]], dtype=np.int32)
    one = np.ones(1)
    _call_address(syrk, (
        flags[0:].ctypes.data, flags[1:].ctypes.data, ints[0:].ctypes.data,
        ints[1:].ctypes.data, one.ctypes.data, Jb.ctypes.data,
        ints[2:].ctypes.data, one.ctypes.data, JtJ.ctypes.data,
        ints[3:].ctypes.data,
    ))  # fmt: skip
    Jtr += np.dot(Jb[:m].T, rb[:m])


@njit(cache=True, inline="always")
def add_row(row, err, Jb, rb, m, JtJ, Jtr, syrk):
    """Append one Jacobian row and its error; return the new fill ``m``."""
    for c in range(row.shape[0]):
        Jb[m, c] = row[c]
    rb[m] = err
    m += 1
    if m == Jb.shape[0]:
        _flush(Jb, rb, m, JtJ, Jtr, syrk)
        m = 0
    return m


@njit(cache=True)
def finish(Jb, rb, m, JtJ, Jtr, syrk):
    """Fold the rows left in the block and complete ``JtJ`` by symmetry."""
    _flush(Jb, rb, m, JtJ, Jtr, syrk)
    for i in range(JtJ.shape[0]):
        for j in range(i):
            JtJ[j, i] = JtJ[i, j]


@njit(cache=True, inline="always")
def copy_rows(dst, src, a, b):
    """``dst[a:b] = src[a:b]`` over the columns of ``dst``."""
    for t in range(a, b):
        for k in range(dst.shape[1]):
            dst[t, k] = src[t, k]


@njit(cache=True, inline="always")
def fill_rows(dst, a, b, x):
    """Every row ``dst[a:b]`` set to ``x[:dst.shape[1]]``."""
    for t in range(a, b):
        for k in range(dst.shape[1]):
            dst[t, k] = x[k]


@njit(cache=True, inline="always")
def keep_step(Z, A, t, z, acts):
    """Network input and hidden activations of row ``t``, for the adjoint pass.

    Skipped when ``Z`` has no rows (nothing will run the adjoint pass); copied
    from contiguous scratch buffers rather than written through row views.
    """
    if Z.shape[0] == 0:
        return
    for i in range(z.shape[0]):
        Z[t, i] = z[i]
    for i in range(A.shape[1]):
        A[t, i] = acts[i]


def jacobian_buffers(want_jac, n_full: int, n_ring: int, n_w: int):
    """Mode and output arrays of a kernel run for an estimator's ``want_jac``.

    ``want_jac`` is False (outputs only), True (the full Jacobian with
    ``n_full`` rows) or ``"normal"`` (the normal equations, with a ring of
    ``n_ring`` Jacobian rows as scratch). Returns ``(mode, J, JtJ, Jtr)``.
    """
    if want_jac == "normal":
        mode, rows = NORMAL, n_ring
    else:
        mode, rows = (FULL_JAC, n_full) if want_jac else (NO_JAC, 0)
    side = n_w if mode == NORMAL else 0
    return mode, np.empty((rows, n_w)), np.zeros((side, side)), np.zeros(side)


def jacobian_result(mode: int, J, JtJ, Jtr):
    """What ``_run`` returns for the Jacobian: None, ``J`` or ``(JtJ, Jtr)``."""
    return {NO_JAC: None, FULL_JAC: J, NORMAL: (JtJ, Jtr)}[mode]
