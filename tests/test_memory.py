"""The freed-memory reuse (jaxparam.memory): process-wide (jp.config.keep_freed_mb) and around
large computations."""
import ctypes
import os
import resource
import subprocess
import sys

import pytest

from jaxparam import memory

pytestmark = pytest.mark.skipif(memory._LIBC is None, reason="needs glibc's mallopt")

#: Set in the process that :func:`test_in_a_fresh_process` starts.
ISOLATED = os.environ.get("JAXPARAM_TEST_MEMORY_ISOLATED") == "1"
#: glibc's malloc state is the whole process's: after the rest of the suite a 64 MiB block can
#: come from memory already faulted in whatever the limits (the always-on run of session 19
#: saw 0 faults where glibc's limits mmap the block), so the checks run in a fresh process.
isolated = pytest.mark.skipif(not ISOLATED, reason="runs in a fresh process (test_in_a_fresh_process)")


def test_in_a_fresh_process():
    if ISOLATED:
        pytest.skip("this is the fresh process")
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", __file__],
                       env={**os.environ, "JAXPARAM_TEST_MEMORY_ISOLATED": "1"},
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert " passed" in r.stdout and "failed" not in r.stdout


def faults_of_second_allocation(nbytes=64 << 20):
    """Minor page faults taken by filling a fresh ``malloc`` block after an equal one was freed
    (straight through the C library, as XLA's and MKL's buffers are)."""
    libc = ctypes.CDLL(None)
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    p = libc.malloc(nbytes)
    ctypes.memset(p, 1, nbytes)
    libc.free(p)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    p = libc.malloc(nbytes)
    ctypes.memset(p, 1, nbytes)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    libc.free(p)
    return faults


@pytest.fixture
def glibc_limits():
    """glibc's largest dynamic limits during the test (a 64 MiB block is mmapped), then
    jp.config's setting back."""
    import jaxparam as jp

    memory.keep_freed(512)            # so that 0 below sets the limits, not "leave alone"
    memory.keep_freed(0)
    yield
    memory.keep_freed(jp.config.keep_freed_mb)


@isolated
def test_keep_freed_keeps_blocks_up_to_its_size(glibc_limits):
    import jaxparam as jp

    pages = (64 << 20) // 4096
    assert faults_of_second_allocation() > pages // 2        # above 32 MiB: mmap per block
    assert memory.keep_freed(128)
    faults_of_second_allocation()                            # grows the heap once
    assert faults_of_second_allocation() < pages // 10       # then the freed block is reused
    assert faults_of_second_allocation(256 << 20) > (256 << 20) // 4096 // 2   # above 128 MiB
    with pytest.raises(ValueError, match=r"\[0, 2047\]"):
        memory.keep_freed(4096)
    jp.config.keep_freed_mb = 64 + 1                         # the setting applies at once
    assert faults_of_second_allocation() < pages // 10
    with pytest.raises(ValueError, match="whole number of MiB"):
        jp.config.keep_freed_mb = "a lot"
    with pytest.raises(ValueError, match=r"\[0, 2047\]"):
        jp.config.keep_freed_mb = -1
    jp.config.keep_freed_mb = 512


@isolated
def test_reuse_inside_ends_at_the_process_wide_setting(glibc_limits):
    memory.keep_freed(128)
    pages = (64 << 20) // 4096
    with memory.reuse_freed_memory(10**6):
        assert faults_of_second_allocation() < pages // 10
    faults_of_second_allocation()
    assert faults_of_second_allocation() < pages // 10       # 128 MiB kept, not glibc's limits


def test_bad_environment_value_warns_and_keeps_the_default(monkeypatch):
    from jaxparam import settings

    monkeypatch.setenv("JAXPARAM_KEEP_FREED_MB", "lots")
    with pytest.warns(UserWarning, match="JAXPARAM_KEEP_FREED_MB"):
        assert settings.default_keep_freed_mb() == 512
    monkeypatch.setenv("JAXPARAM_KEEP_FREED_MB", "0")
    assert settings.default_keep_freed_mb() == 0
    monkeypatch.setenv("JAXPARAM_KEEP_FREED_MB", "4096")
    with pytest.warns(UserWarning, match=r"JAXPARAM_KEEP_FREED_MB must be in \[0, 2047\]"):
        assert settings.default_keep_freed_mb() == 512
    assert settings.MAX_KEEP_MB == memory.MAX_KEEP_MB


@isolated
def test_freed_blocks_are_reused_inside_and_returned_outside(glibc_limits):
    pages = (64 << 20) // 4096
    assert faults_of_second_allocation() > pages // 2        # glibc's limits: mmap per block
    with memory.reuse_freed_memory(10**6):
        faults_of_second_allocation()                        # grows the heap once
        assert faults_of_second_allocation() < pages // 10
        with memory.reuse_freed_memory(10**6):               # nested: still on
            assert faults_of_second_allocation() < pages // 10
        assert faults_of_second_allocation() < pages // 10   # the inner exit left it on
    assert faults_of_second_allocation() > pages // 2        # restored


@isolated
def test_small_problems_change_nothing(glibc_limits):
    pages = (64 << 20) // 4096
    with memory.reuse_freed_memory(memory.MIN_SIZE - 1):
        assert faults_of_second_allocation() > pages // 2
