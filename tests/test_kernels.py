"""The numba kernels compile once per kind of input: a specialization costs seconds of the first
run (docs/design.md, "Writing the mesh and the first run")."""

import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "bench"

# Run in a fresh process: other tests call kernels directly, with inputs of their own.
_CHECK = f"""
import gc
import sys
from numba import types
from numba.core.registry import CPUDispatcher
sys.path.insert(0, r"{BENCH}")
from compare import warm_up_paroct

def kind(t):
    # Array flags (read-only, layout) and literal values change no kernel's code.
    if isinstance(t, types.Array):
        return ("array", str(t.dtype), t.ndim)
    if isinstance(t, types.Literal):
        return str(t.literal_type)
    return str(t)

# Every path: graded, uniform, pinch repair, thin features, brick-directory numbering (the
# benchmark's warm-up, which must load every kernel before its timed calls).
warm_up_paroct()
n = 0
for obj in gc.get_objects():
    if isinstance(obj, CPUDispatcher) and obj.py_func.__module__.startswith("paroct"):
        kinds = [tuple(kind(t) for t in sig) for sig in obj.signatures]
        n += len(kinds)
        if len(set(kinds)) < len(kinds):
            print(f"{{obj.py_func.__module__}}.{{obj.py_func.__name__}}: {{obj.signatures}}")
print("specializations", n)
"""


def test_no_kernel_is_compiled_twice_for_the_same_kind_of_input():
    run = subprocess.run([sys.executable, "-c", _CHECK], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.strip().splitlines()
    assert lines[-1].startswith("specializations") and int(lines[-1].split()[1]) > 40, run.stdout
    twice = lines[:-1]
    assert not twice, "compiled again for a read-only or non-contiguous array or a literal:\n" + "\n".join(twice)
