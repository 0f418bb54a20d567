"""Fused multiply-add for the kernels: ``x * y + z`` rounded once, the same bits compiled and as Python.

Used by the CD pair kernels (:mod:`clusterdyn.engine.pair`, their table polynomial) and by the set-up
tessellation (:mod:`clusterdyn.build.tessellation`, which repeats numpy's fused BLAS dot products)."""
from fractions import Fraction

from llvmlite import ir
from numba import config
from numba.core import cgutils, types
from numba.extending import intrinsic


@intrinsic
def _fma(typingctx, x, y, z):
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(d, [d, d, d]), "llvm.fma.f64")
        return builder.call(fn, args)
    return sig, codegen


def _fma_python(x, y, z):
    return float(Fraction(x) * Fraction(y) + Fraction(z))   # exact, then rounded once


#: ``fma(x, y, z)``: ``x * y + z`` rounded once, IEEE 754's fused multiply-add.  Compiled, it is
#: LLVM's ``llvm.fma.f64``: one instruction where the CPU has FMA, libm's ``fma`` where not, the
#: same bits on every CPU (unlike letting the compiler contract ``x * y + z`` where it likes).
#: Under ``NUMBA_DISABLE_JIT=1`` (debugging the kernels as Python) it is the same sum in exact
#: rational arithmetic, rounded once: the same bits again.
fma = _fma_python if config.DISABLE_JIT else _fma
