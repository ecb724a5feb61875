"""Two processes compiling at once (``active-contacts warm``, the test workers) save versions
of one kernel to numba's cache at once: the toolkit's kernels save under a lock, so that each
save reads the index the other wrote and every version keeps its own machine code."""

from __future__ import annotations

import threading

import pytest

numba_caching = pytest.importorskip("numba.core.caching")

from toolkit._compiled import _locked  # noqa: E402

#: How long the first save holds its window open for the second (s): under the lock the
#: second cannot enter it, and the first goes on after this wait.
WINDOW = 0.5


def _two_saves_at_once(kind: type, folder: str) -> object:
    """Save versions ``"a"`` and ``"b"`` of one kernel with ``kind`` (numba's cache file class
    or the toolkit's locked one) from two threads, the second started while the first has
    read the index and not yet written it (numba's window); returns a cache file to read."""
    first, second = kind(folder, "kernel", "stamp"), kind(folder, "kernel", "stamp")
    read_by_first, read_by_second = threading.Event(), threading.Event()
    load_index, save_index = first._load_index, first._save_index

    def first_loads() -> dict:
        overloads = load_index()
        read_by_first.set()
        return overloads

    def first_saves(overloads: dict) -> None:
        read_by_second.wait(WINDOW)          # (the second reads the index now, if it can)
        save_index(overloads)

    def second_loads() -> dict:
        overloads = second.__class__._load_index(second)
        read_by_second.set()
        return overloads

    first._load_index, first._save_index, second._load_index = first_loads, first_saves, second_loads

    def second_saves() -> None:
        read_by_first.wait(10 * WINDOW)
        second.save("b", "machine code b")

    thread = threading.Thread(target=second_saves)
    thread.start()
    first.save("a", "machine code a")
    thread.join()
    return kind(folder, "kernel", "stamp")


def test_locked_saves_keep_every_version_with_its_own_code(tmp_path):
    cache = _two_saves_at_once(_locked(numba_caching.IndexDataCacheFile), str(tmp_path))
    assert cache.load("a") == "machine code a"
    assert cache.load("b") == "machine code b"
    assert sorted(cache._load_index().values()) == ["kernel.1.nbc", "kernel.2.nbc"]


def test_numbas_own_saves_lose_a_version_in_that_window(tmp_path):
    # The race the lock removes, on numba's class: both saves read the empty index and take
    # the first data file's name, so the index keeps one version of the two (and the file it
    # names holds whichever machine code was written last: with the writes interleaved the
    # other way, one version's name would load the other's code).
    cache = _two_saves_at_once(numba_caching.IndexDataCacheFile, str(tmp_path))
    index = cache._load_index()
    assert len(index) == 1 and list(index.values()) == ["kernel.1.nbc"], index


def test_where_files_cannot_be_locked_the_save_is_numbas_own(tmp_path, monkeypatch):
    import filelock

    def refuse(self, *args, **kwargs):
        raise NotImplementedError("FileSystem does not appear to support flock")

    monkeypatch.setattr(filelock.FileLock, "acquire", refuse)
    cache = _locked(numba_caching.IndexDataCacheFile)(str(tmp_path), "kernel", "stamp")
    cache.save("a", "machine code a")
    assert cache.load("a") == "machine code a"


def test_the_toolkits_kernels_save_under_the_lock():
    from toolkit import _compiled

    module = _compiled.load("core")
    dispatchers = [getattr(module, name) for name in module.KERNELS]
    cached = [d for d in dispatchers if getattr(d, "_cache", None) is not None
              and hasattr(d._cache, "_cache_file")]
    if not cached:
        pytest.skip("kernels run as Python (NUMBA_DISABLE_JIT): nothing is cached")
    assert all(type(d._cache._cache_file).__name__.startswith("Locked") for d in cached)
