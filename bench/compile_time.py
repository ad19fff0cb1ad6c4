"""Where numba's cold compile time goes: seconds per function, with an empty cache.

    python bench/compile_time.py [--top 25] [--tests [PYTEST_ARGS ...] | --mesh SURFACE]

By default a child process with a fresh, temporary NUMBA_CACHE_DIR meshes
compare.warm_up_paroct's parts, which take every path of the mesher. With ``--tests`` it runs
pytest instead, in one process (`-p no:xdist`), over the arguments given (default: tests),
which is what a fresh clone's CI compiles.  With ``--mesh`` it runs the program,
``paroct mesh SURFACE -q`` (the output in the temporary folder): what a user's first
run compiles, such as the README's (``--mesh data/angle_block.stl``; 150 s in 121 functions
in session 53).  A listener on numba's ``numba:compile`` events
times each compile. A function's *exclusive* seconds leave out the compiles of the callees
it set off (numba compiles a called kernel inside its caller's compile). The script prints:

- the total, and the top functions by exclusive seconds with their inclusive seconds and how
  many times each compiled;
- the paroct functions compiled more than once, with the arguments of each compile: int32
  against int64 arrays, an F-order array, None for an optional argument, a literal (an
  overload's implementation, `_overload_*.<locals>`, compiles again in each kernel that
  calls it, with the same arguments).

Session 52 (docs/design.md, "The test suite on a fresh clone") found one kernel taking 65 s of a cold
suite's 549 s this way.  A compile is timed on a machine doing nothing else, like any
benchmark here. These are not tests.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: Installed in the child (as a pytest plugin with --tests): records every compile's seconds,
#: exclusive of the compiles it set off, and writes them to the JSON path in argv[1].
_RECORDER = r'''
import atexit, json, sys, time
from numba.core import event

_stack, _rows = [], {}

class _Recorder(event.Listener):
    def on_start(self, ev):
        d = ev.data["dispatcher"]
        _stack.append([f"{d.py_func.__module__}.{d.py_func.__qualname__}", time.perf_counter(), 0.0])

    def on_end(self, ev):
        name, start, callees = _stack.pop()
        seconds = time.perf_counter() - start
        row = _rows.setdefault(name, [0.0, 0.0, []])
        row[0] += seconds - callees
        row[1] += seconds
        row[2].append(str(ev.data["args"]))
        if _stack:
            _stack[-1][2] += seconds

event.register("numba:compile", _Recorder())
_OUT = __OUT__
atexit.register(lambda: json.dump(_rows, open(_OUT, "w")))
'''


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--top", type=int, default=25, help="functions listed by exclusive seconds")
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--tests", nargs="*", default=None, metavar="PYTEST_ARG",
                      help="compile what pytest runs (default arguments: tests) instead of the warm-up meshes")
    what.add_argument("--mesh", default=None, metavar="SURFACE",
                      help="compile what `paroct mesh SURFACE -q` runs (SURFACE relative to the repository)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "compiles.json"
        recorder = Path(scratch) / "compile_recorder.py"
        recorder.write_text(_RECORDER.replace("__OUT__", repr(str(out))))
        env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(scratch) / "cache"),
                   PYTHONPATH=os.pathsep.join([scratch, str(HERE), os.environ.get("PYTHONPATH", "")]))
        if args.mesh is not None:
            program = (f"import compile_recorder, sys; from paroct.cli import main; "
                       f"sys.exit(main(['mesh', {args.mesh!r}, '-q', '-o', {str(Path(scratch) / 'first.vtu')!r}]))")
            command = [sys.executable, "-c", program]
        elif args.tests is None:
            command = [sys.executable, "-c", "import compile_recorder, compare; compare.warm_up_paroct()"]
        else:
            command = [sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-p", "no:cacheprovider",
                       "-p", "compile_recorder", *(args.tests or ["tests"])]
        run = subprocess.run(command, env=env, cwd=HERE.parent)
        if not out.exists():
            print(f"the child exited with {run.returncode} before writing its compiles", file=sys.stderr)
            return 1
        rows = json.loads(out.read_text())
    ranked = sorted(rows.items(), key=lambda kv: -kv[1][0])
    print(f"{sum(r[0] for r in rows.values()):.1f} s compiling, {len(rows)} functions")
    print(f"{'exclusive':>9} {'inclusive':>9} {'times':>5}  function")
    for name, (exclusive, inclusive, signatures) in ranked[:args.top]:
        print(f"{exclusive:9.1f} {inclusive:9.1f} {len(signatures):5d}  {name}")
    again = [(name, row) for name, row in ranked if len(row[2]) > 1 and name.startswith("paroct")]
    print(f"\n{len(again)} paroct functions compiled more than once "
          f"({sum(row[0] * (len(row[2]) - 1) / len(row[2]) for _, row in again):.1f} s, split evenly):")
    for name, (exclusive, _, signatures) in again:
        print(f"{exclusive:9.1f}  {name}")
        for signature in signatures:
            print(f"           {signature}")
    return run.returncode


if __name__ == "__main__":
    sys.exit(main())
