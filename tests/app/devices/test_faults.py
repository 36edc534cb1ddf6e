"""FaultInjector: each fault kind does to a reply what its docstring says."""

import math

import numpy as np
import pytest

from app.devices.faults import FAULT_KINDS, Fault, FaultInjector

REPLY = b"g0g+00012345\r\n"


def one(fault, reply=REPLY, **kw):
    inj = FaultInjector(np.random.default_rng(0), **kw)
    inj.push(fault)
    return inj.process(reply)


def joined(delivery):
    return b"".join(chunk for _, chunk in delivery.chunks)


def test_no_fault_passes_the_reply_unchanged():
    d = FaultInjector(0).process(REPLY)
    assert d.chunks == [(0.0, REPLY)] and d.fault is None and not d.unplug


def test_drop_late_split():
    assert one("drop").chunks == []
    late = one(Fault("late", delay_s=0.7))
    assert late.chunks == [(0.7, REPLY)]
    split = one(Fault("split", at=5, delay_s=0.05))
    assert split.chunks == [(0.0, REPLY[:5]), (0.05, REPLY[5:])]


def test_truncate_keeps_a_prefix_with_or_without_terminator():
    assert joined(one(Fault("truncate", at=6))) == b"g0g+00"
    assert joined(one(Fault("truncate", at=6, keep_terminator=True))) == b"g0g+00\r\n"
    default = joined(one("truncate"))
    assert REPLY.startswith(default) and len(default) == len(REPLY.rstrip()) // 2


def test_junk_is_a_prefix_without_line_ends():
    out = joined(one("junk"))
    assert out.endswith(REPLY) and len(out) > len(REPLY)
    assert b"\r" not in out[: -len(REPLY)] and b"\n" not in out[: -len(REPLY)]
    assert joined(one(Fault("junk", data=b"\x00\xff"))) == b"\x00\xff" + REPLY


def test_garble_changes_exactly_one_byte_of_the_text():
    out = joined(one("garble"))
    assert len(out) == len(REPLY) and out.endswith(b"\r\n")
    assert sum(a != b for a, b in zip(out, REPLY)) == 1
    assert joined(one(Fault("garble", at=11, data=b"7"))) == b"g0g+00012347\r\n"


def test_unsolicited_error_and_unplug_use_the_device_defaults():
    d = one("unsolicited", unsolicited_line=b"g0?\r\n")
    assert joined(d) == b"g0?\r\n" + REPLY
    assert joined(one("error", error_line=b"g0@E260\r\n")) == b"g0@E260\r\n"
    u = one(Fault("unplug", delay_s=0.2))
    assert u.unplug and u.replug_after_s == 0.2 and u.chunks == []
    assert one(Fault("unplug", delay_s=math.inf)).replug_after_s == math.inf


def test_queued_faults_apply_in_order_and_match_waits_for_its_reply():
    inj = FaultInjector(0)
    inj.push(Fault("drop", match=b"g0t"), "late")
    assert inj.process(REPLY).fault is None  # the head of the queue waits for a g0t reply
    assert inj.process(b"g0t+00000240\r\n").fault.kind == "drop"
    assert inj.process(REPLY).fault.kind == "late"
    assert inj.pending == 0 and [k for k, _ in inj.applied] == ["drop", "late"]


def test_random_rates_are_seeded_and_roughly_right():
    a = FaultInjector(np.random.default_rng(3), {"drop": 0.2, "garble": 0.1})
    b = FaultInjector(np.random.default_rng(3), {"drop": 0.2, "garble": 0.1})
    kinds_a = [a.process(REPLY).fault for _ in range(2000)]
    kinds_b = [b.process(REPLY).fault for _ in range(2000)]
    assert kinds_a == kinds_b
    drops = sum(f is not None and f.kind == "drop" for f in kinds_a)
    garbles = sum(f is not None and f.kind == "garble" for f in kinds_a)
    assert 330 < drops < 470 and 140 < garbles < 260


def test_bad_faults_and_rates_are_refused():
    with pytest.raises(ValueError, match="unknown fault kind"):
        Fault("explode")
    with pytest.raises(ValueError, match="1 byte"):
        Fault("garble", data=b"ab")
    with pytest.raises(ValueError, match="add up"):
        FaultInjector(0, {"drop": 0.7, "late": 0.6})
    with pytest.raises(ValueError, match="within"):
        FaultInjector(0, {"drop": 1.5})
    assert set(FAULT_KINDS) >= {"drop", "late", "truncate", "split", "junk", "garble", "unsolicited", "error", "unplug"}


def test_an_early_reply_is_a_complete_reply_of_the_same_form_with_another_value():
    inj = FaultInjector(5)
    for reply in (b"g0g+00014603\r\n", b"* 1234\r\n", b"* -907\r\n"):
        inj.push("early")
        d = inj.process(reply)
        (_, fake), (_, real) = d.chunks
        assert real == reply and fake != reply and fake.endswith(b"\r\n") and len(fake) == len(reply)
        assert fake[: fake.find(b"+") if b"+" in fake else 1] == reply[: reply.find(b"+") if b"+" in reply else 1]
    inj.push(Fault("early", data=b"g0g+00000500\r\n"))
    assert [c for _, c in inj.process(b"g0g+00014603\r\n").chunks] == [b"g0g+00000500\r\n", b"g0g+00014603\r\n"]
    inj.push("early")
    assert [c for _, c in inj.process(b"*\r\n").chunks] == [b"*\r\n", b"*\r\n"]  # no value: the same reply twice
