"""forked_map: chunks in order, closures through fork, work really done in other processes, the
same results one after the other; chunked."""
import os

import numpy as np
import pytest

from stringcast.core import chunked, forked_map


def test_chunks_come_back_in_order_from_worker_processes():
    big = np.arange(1000.0)                   # inherited by the workers, not sent

    def work(part):
        return [(int(k), float(big[k] ** 2), os.getpid()) for k in part]

    chunks = chunked(np.arange(0, 1000, 7), 5)
    par = [r for part in forked_map(work, chunks, 2) for r in part]
    seq = [r for part in forked_map(work, chunks, 1) for r in part]
    assert [r[:2] for r in par] == [r[:2] for r in seq] == [(k, k * k) for k in range(0, 1000, 7)]
    assert {r[2] for r in seq} == {os.getpid()}
    assert os.getpid() not in {r[2] for r in par}        # the work ran in forked workers


def test_a_worker_error_reaches_the_caller_and_nesting_is_refused():
    def fails(part):
        if 3 in part:
            raise ValueError("chunk with 3")
        return part

    with pytest.raises(ValueError, match="chunk with 3"):
        list(forked_map(fails, chunked(list(range(8)), 2), 2))

    outer = forked_map(lambda p: p, [[1], [2]], 2)
    next(outer)                                    # one map running: a second one is refused
    try:
        with pytest.raises(RuntimeError, match="already running"):
            list(forked_map(lambda p: p, [[1], [2]], 2))
    finally:
        outer.close()


def test_chunked_splits_in_order():
    assert chunked(list(range(7)), 3) == [[0, 1, 2], [3, 4, 5], [6]]
    assert [list(c) for c in chunked(np.arange(4), 10)] == [[0, 1, 2, 3]]
