"""Loop layout shared by the kernel modules."""
import taichi as ti
from taichi.lang import impl

THREAD_SPAN = 512  # Taichi's CPU range-for gives each thread a run of at least this many iterations


def thread_span(serial: bool) -> int:
    """Iterations per unit of work in a loop meant to split a few units over the CPU threads (compile time):
    THREAD_SPAN on a CPU runtime, so that each unit starts a thread's run (a loop over a few dozen units
    would otherwise run on one thread), and 1 for serial loops and GPUs (one thread per unit)."""
    return 1 if serial or impl.current_cfg().arch not in (ti.x64, ti.arm64) else THREAD_SPAN
