"""prlpid_fmi.runcontext: a run's measurements and FMU call timeout belong to the run and end with it."""
from prlpid_fmi import runcontext
from prlpid_fmi.fmu import watchdog
from prlpid_fmi.runcontext import CACHE_LIMIT, RunContext


class _Plant:
    step_timeout_s = None


def test_an_opened_context_is_current_inside_its_block_and_the_one_before_after_it():
    before = runcontext.current()
    with runcontext.opened(step_timeout_s=7.0) as run:
        assert runcontext.current() is run and run.measured == {} and run.references == {}
        assert watchdog.timeout_of(_Plant()) == (7.0, "--step-timeout")  # the run's timeout reaches every call
        with runcontext.opened() as inner:
            assert runcontext.current() is inner and inner.step_timeout_s is None
        assert runcontext.current() is run
    assert runcontext.current() is before


def test_keep_drops_the_oldest_entry_at_the_limit():
    cache: dict = {}
    for i in range(CACHE_LIMIT + 3):
        RunContext.keep(cache, i, i)
    assert len(cache) == CACHE_LIMIT and min(cache) == 3 and max(cache) == CACHE_LIMIT + 2
    RunContext.keep(cache, 10, "again")  # a key already kept is replaced, nothing dropped
    assert len(cache) == CACHE_LIMIT and cache[10] == "again" and min(cache) == 3
