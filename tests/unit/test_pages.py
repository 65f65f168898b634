"""``vnav_graph.util.pages.small_pages``: numpy's huge-page setting off inside, restored after."""

from __future__ import annotations

import threading

import pytest

from vnav_graph.util import pages as pages


def _state() -> bool:
    setter = pages.numpy_hugepage_setter()
    prev = bool(setter(True))
    setter(prev)
    return prev


@pytest.fixture
def setter():
    s = pages.numpy_hugepage_setter()
    if s is None:
        pytest.skip("this numpy has no huge-page switch")
    before = _state()
    yield s
    s(before)


@pytest.mark.parametrize("initial", [True, False])
def test_off_inside_and_the_callers_setting_back_after(setter, initial):
    setter(initial)
    with pages.small_pages():
        assert _state() is False
        with pages.small_pages():  # nested: still off, and the outer exit restores
            assert _state() is False
        assert _state() is False
    assert _state() is initial


def test_restored_after_an_exception(setter):
    setter(True)
    with pytest.raises(RuntimeError), pages.small_pages():
        raise RuntimeError("solver failed")
    assert _state() is True


def test_overlapping_threads_restore_only_when_the_last_leaves(setter):
    setter(True)
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    seen: dict[str, bool] = {}

    def first() -> None:
        with pages.small_pages():
            a_in.set()
            b_in.wait(5)
        a_out.set()

    def second() -> None:
        a_in.wait(5)
        with pages.small_pages():
            b_in.set()
            a_out.wait(5)
            seen["after the first left"] = _state()

    ts = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in ts:
        t.start()
    for t in ts:
        t.join(10)
    assert seen == {"after the first left": False}
    assert _state() is True
