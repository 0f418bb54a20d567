"""Typed errors.

* :class:`InputError` (a :class:`ValueError`): bad input before a run; the
  message names the argument, the value given and what is allowed.
* :class:`InstabilityError` (an :class:`ase.calculators.calculator.CalculationFailed`):
  physics out of range during a run; the message names the step, the
  particles and the quantity.
"""

from ase.calculators.calculator import CalculationFailed


class InputError(ValueError):
    """Bad input: names the argument, the value and what is allowed."""

    def __init__(self, argument, value, allowed, hint=None):
        self.argument = argument
        self.value = value
        self.allowed = allowed
        self.hint = hint
        msg = f"{argument}={value!r} is not allowed: expected {allowed}"
        if hint:
            msg += f" ({hint})"
        super().__init__(msg)


class InstabilityError(CalculationFailed):
    """A run left the range where the model is valid (names step, particles, quantity)."""

    def __init__(self, message, step=None, particles=None, quantity=None, value=None, limit=None):
        self.message = message
        self.step = step
        self.particles = tuple(int(p) for p in particles) if particles is not None else ()
        self.quantity = quantity
        self.value = value
        self.limit = limit
        parts = [message]
        if step is not None:
            parts.append(f"step {step}")
        if self.particles:
            parts.append("particle" + ("s " if len(self.particles) > 1 else " ")
                         + ", ".join(str(p) for p in self.particles))
        if quantity is not None:
            q = f"{quantity} = {value:.6g}" if value is not None else str(quantity)
            if limit is not None:
                q += f" (limit {limit:.6g})"
            parts.append(q)
        super().__init__("; ".join(parts))


def check_positive(name, value, allow_zero=False):
    """Raise InputError unless ``value`` is a finite positive number."""
    import math
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(name, value, "a number") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise InputError(name, value, "a finite number >= 0" if allow_zero else "a finite number > 0")
    return v


class OutputError(OSError):
    """Writing an output file failed (full disk, file too large, no permission).

    The message names the file, the cause and what is kept (e.g. the last
    checkpoint and the H5MD frames written before); the CLI prints it in one
    line and exits with status 1.
    """

    def __init__(self, path, cause, kept=None):
        import errno as _errno
        self.path = str(path)
        self.cause = cause
        self.kept = kept
        code = getattr(cause, "errno", None)
        if code is None:                 # h5py's RuntimeError: find the errno in HDF5's message
            import re
            m = re.search(r"errno = (\d+)", str(cause))
            code = int(m.group(1)) if m else None
        import os
        why = os.strerror(code) if code else (str(cause).splitlines()[0] if str(cause) else type(cause).__name__)
        msg = f"cannot write {self.path}: {why}"
        if kept:
            msg += f"; kept: {kept}"
        super().__init__(code if code is not None else _errno.EIO, msg)
        self.message = msg

    def __str__(self):
        return self.message


#: set by the CLI's SIGINT handler; a run checks it at every step and frame, so an interrupt
#: that a library swallowed ("Exception ignored in ...") still stops the run there
INTERRUPTED = [False]
#: > 0 while a run steps: the CLI's SIGINT handler then only sets INTERRUPTED, and the run raises
#: KeyboardInterrupt at its next step, from Python: an exception raised inside a numba or h5py
#: callback would come out as a SystemError (a second SIGINT raises at once)
DEFER_INTERRUPT = [0]


def check_interrupt():
    """Raise KeyboardInterrupt if a SIGINT arrived (see :data:`INTERRUPTED`)."""
    if INTERRUPTED[0]:
        raise KeyboardInterrupt
