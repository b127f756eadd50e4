"""Verdicts: the worse status wins, every reason is kept, and they round-trip through JSON."""
import pytest

from stringcast.core import Verdict, worst


def test_add_keeps_the_worse_status_and_every_reason():
    v = Verdict().add("warn", "principal point poorly determined").add("ok", "note")
    assert v.status == "warn" and v.reasons == ("principal point poorly determined", "note")
    assert v.add("fail", "no board").status == "fail"
    assert Verdict.from_dict(v.as_dict()) == v and Verdict.from_dict(None).ok


def test_worst_of_several_and_bad_input():
    w = worst(Verdict(), Verdict("warn", ("a",)), Verdict("fail", ("b",)))
    assert w.status == "fail" and w.reasons == ("a", "b")
    with pytest.raises(ValueError, match="status"):
        Verdict("bad")
    with pytest.raises(ValueError, match="reason"):
        Verdict("fail")
