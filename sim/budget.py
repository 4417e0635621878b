"""Work and memory budget of one simulation, checked before anything is allocated or integrated.

The integrator's step follows the stiffest mode and its output grid the requested spacing, so a
stiff (but valid) vehicle, a long input or a tiny ``output_dt`` can ask for billions of steps
or gigabytes of output. Inside the service a compiled kernel cannot be interrupted, so such a
run is refused up front with the numbers instead of hanging or ending in ``MemoryError``.
"""

from __future__ import annotations

from sim.errors import InputSignalError, ParameterError

MAX_STEPS = 200_000_000  # integrator steps of one run (about 10-20 s of compiled work for the paper chain)
MAX_BATCH_STEPS = 10 * MAX_STEPS  # all variants of a batch together
MAX_OUTPUT_BYTES = 2 * 2**30  # output arrays of one call (kernel buffers and result arrays); ~110 min at 1 ms


def check_output(span_s: float, output_dt: float, n_out: int, bytes_per_row: int) -> None:
    """Refuse an output grid of ``n_out`` rows of ``bytes_per_row`` bytes over ``MAX_OUTPUT_BYTES``.

    Raises
    ------
    InputSignalError : naming the input span (s), ``output_dt`` (s), rows and bytes
    """
    size = n_out * bytes_per_row
    if size > MAX_OUTPUT_BYTES:
        raise InputSignalError(
            f"input spans {span_s:.6g} s at output_dt = {output_dt:.6g} s: {n_out:.4g} output samples, "
            f"{size / 2**20:.4g} MiB of output, over the budget of {MAX_OUTPUT_BYTES / 2**20:.0f} MiB; "
            f"simulate a shorter window or a larger output_dt (at most {MAX_OUTPUT_BYTES // bytes_per_row:.4g} "
            f"samples)")


def check_steps(span_s: float, step: float, n_steps: int, *, auto: bool, limit: int = MAX_STEPS,
                what: str = "run") -> None:
    """Refuse ``n_steps`` integrator steps of ``step`` s over ``limit``.

    Raises
    ------
    ParameterError : field ``dt`` with the step, naming the span, step count and budget
    """
    if n_steps <= limit:
        return
    cause = ("the automatic step follows the stiffest mode: check stiffness and inertia values"
             if auto else "choose a larger dt")
    raise ParameterError(
        "dt", step, f"{n_steps:.4g} integrator steps for {span_s:.6g} s of input ({what}) exceed the budget of "
        f"{limit:.4g} steps; {cause}, or simulate a shorter window")


__all__ = ["MAX_BATCH_STEPS", "MAX_OUTPUT_BYTES", "MAX_STEPS", "check_output", "check_steps"]
