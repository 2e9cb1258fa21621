"""Process settings of the compute-heavy jobs."""

from __future__ import annotations

import platform

import pytest

from tohgs.runtime import keep_freed_memory


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc only")
def test_glibc_takes_the_allocator_settings():
    assert keep_freed_memory() is True
    assert keep_freed_memory(mmap_threshold=128 << 10, trim_threshold=128 << 10) is True  # glibc's defaults back
