"""The campaign's worker processes run one BLAS thread each, whatever their parent had."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

from threadpoolctl import threadpool_info, threadpool_limits

from pipeline.diagnosis.campaign import one_blas_thread


def _blas_threads() -> list:
    return sorted({d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"})


def test_a_forked_worker_keeps_its_parents_blas_threads_unless_limited():
    # The parent's pool is set to two threads; a worker forked from it inherits that pool (an
    # environment variable set now would come too late), so only the initializer limits it.
    with threadpool_limits(limits=2, user_api="blas"):
        parent = _blas_threads()
        with ProcessPoolExecutor(1) as ex:
            plain = ex.submit(_blas_threads).result()
        with ProcessPoolExecutor(1, initializer=one_blas_thread) as ex:
            limited = ex.submit(_blas_threads).result()
    assert parent == [2]
    assert plain == [2]
    assert limited == [1]
