"""Process memory for the benchmarks (Linux /proc): current and peak size, peak reset, heap trim."""


def status(key):
    """A size field of /proc/self/status in bytes (``VmRSS``: resident now, ``VmHWM``: peak); -1 when
    the field is missing."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    return -1


def reset_peak():
    """Reset the peak resident size (VmHWM) to the current one; False where the kernel does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def trim():
    """glibc's malloc_trim(0): free heap pages (e.g. left by h5py's chunked reads or a builder) go back
    to the system, so the process' size counts memory in use."""
    try:
        import ctypes
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
