"""The README runs the tests in two pytest-xdist workers (-n 2): on a fresh clone most of the
time is numba compiling kernels into their cache, and two processes compile two kernels at
once (cold, 2 cores: 13:16 in one process, 6:32 in two with the setting below).

Each worker's OpenMP threads must sleep when idle (paroct.cli.let_idle_threads_sleep, as
the program does): spinning, two workers' waiting threads hold the cores the other needs,
and the warm suite took 255 s in two workers against 213 s in one; asleep, 134 s.  Set
before numba first starts its threads, unless the environment says otherwise."""

import os

from paroct.cli import let_idle_threads_sleep

if "PYTEST_XDIST_WORKER" in os.environ:
    let_idle_threads_sleep()
