"""The public planners run with one BLAS thread whoever calls them, and give the caller its setting back."""

from __future__ import annotations

import pytest
from threadpoolctl import ThreadpoolController, threadpool_limits

import planners
from planners.blas import single_blas_thread


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in ThreadpoolController().select(user_api="blas").info()]


def test_a_wrapped_function_sees_one_blas_thread_and_the_caller_keeps_its_own():
    if not _blas_threads():
        pytest.skip("numpy is linked to no BLAS threadpoolctl can see")
    seen = []
    wrapped = single_blas_thread(lambda: seen.append(_blas_threads()) or 7)
    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        assert wrapped() == 7
        assert _blas_threads() == before
    assert seen == [[1] * len(before)]


@pytest.mark.parametrize("name", ["plan_gait_cycle", "plan_cog"])
def test_the_public_planners_limit_blas_themselves(name):
    func = getattr(planners, name)
    wrapper_code = single_blas_thread(lambda: None).__code__  # every function it wraps runs this code
    assert func.__code__ is wrapper_code, f"planners.{name} is not wrapped by single_blas_thread"
