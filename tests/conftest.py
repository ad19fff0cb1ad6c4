"""The README runs the tests in two pytest-xdist workers (-n 2): on a fresh clone most of the
time is numba compiling kernels into their cache, and two processes compile two kernels at
once (cold, 2 cores: 13:16 in one process, 6:32 in two with the setting below).

Each worker's OpenMP threads must sleep when idle, as in console_main (paroct.cli): spinning,
two workers' waiting threads hold the cores the other needs, and the warm suite took 255 s
in two workers against 213 s in one; asleep, 134 s.  Set before numba first starts its
threads, unless the environment says otherwise."""

import os

if "PYTEST_XDIST_WORKER" in os.environ and "GOMP_SPINCOUNT" not in os.environ:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
