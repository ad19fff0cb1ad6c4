"""Resident memory of this process, for reports and benchmarks.

Linux only (/proc/self); elsewhere every function returns None and callers report nothing.
"""

from __future__ import annotations


def _status_bytes(field: str) -> int | None:
    """A ``kB`` field of /proc/self/status (VmRSS: resident now, VmHWM: peak) in bytes."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def start_peak_count() -> int | None:
    """Restart the kernel's count of this process's peak resident memory and return the
    resident bytes now, or None where the peak cannot be restarted (not Linux >= 4.0).

    Without the restart, the peak after a call would include everything before it (numba's
    and manifold3d's imports alone peak near 0.2 GiB), so a small mesh would read 0.
    """
    try:
        with open("/proc/self/clear_refs", "w") as refs:
            refs.write("5")  # 5: reset the peak RSS (proc(5), clear_refs)
    except OSError:
        return None
    return _status_bytes("VmRSS")


def peak_resident() -> int | None:
    """Peak resident bytes of this process since start_peak_count (or since it started)."""
    return _status_bytes("VmHWM")
