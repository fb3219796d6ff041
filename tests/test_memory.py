"""The freed-memory reuse around large computations (jaxparam.memory)."""
import ctypes
import resource

import pytest

from jaxparam import memory

pytestmark = pytest.mark.skipif(memory._LIBC is None, reason="needs glibc's mallopt")


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


def test_freed_blocks_are_reused_inside_and_returned_outside():
    pages = (64 << 20) // 4096
    assert faults_of_second_allocation() > pages // 2        # glibc's default: mmap per block
    with memory.reuse_freed_memory(10**6):
        faults_of_second_allocation()                        # grows the heap once
        assert faults_of_second_allocation() < pages // 10
        with memory.reuse_freed_memory(10**6):               # nested: still on
            assert faults_of_second_allocation() < pages // 10
        assert faults_of_second_allocation() < pages // 10   # the inner exit left it on
    assert faults_of_second_allocation() > pages // 2        # restored


def test_small_problems_change_nothing():
    pages = (64 << 20) // 4096
    with memory.reuse_freed_memory(memory.MIN_SIZE - 1):
        assert faults_of_second_allocation() > pages // 2
