"""Property-based fuzz of the protocol parser and the broker: no client input raises, or answers a request."""

from __future__ import annotations

import json

from hypothesis import given, settings
from hypothesis import strategies as st

from mrguide.annotation.broker import AnnotationBroker
from mrguide.annotation.protocol import MAX_REASON, REFUSALS, ProtocolError, parse_answer, parse_hello, parse_message
from mrguide.robot import load_robot

JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=10), inner, max_size=5),
    max_leaves=20,
)
MESSAGES = st.fixed_dictionaries(
    {"type": st.sampled_from(["hello", "claim", "answer", "skip", "ping", "bogus", 3, None])},
    optional={
        "id": JSON,
        "target": JSON | st.lists(st.floats(), min_size=3, max_size=3),
        "vacuum": JSON,
        "protocol": JSON,
    },
)


#: What a hostile client sends beside random JSON: deep nesting, numbers of hundreds or thousands of digits
#: (Python refuses ints of more than 4,300 and overflows on converting ints of 400 to float), odd versions.
HOSTILE = st.one_of(
    st.integers(1, 20_000).map(lambda depth: '{"type": "ping", "x": ' + "[" * depth + "]" * depth + "}"),
    st.integers(19, 6_000).map(
        lambda n: '{"type": "answer", "id": "a", "target": [1' + "0" * n + ', 0, 0.1], "vacuum": true}'
    ),
    st.sampled_from(["true", '"1"', "1.0", "2", "null", "[]", "1e400", "-0"]).map(
        lambda v: '{"type": "hello", "protocol": ' + v + "}"
    ),
    st.text(alphabet=st.characters(codec="utf-8"), max_size=30).map(
        lambda t: json.dumps({"type": "answer", "id": t, "target": t})
    ),
)


@settings(max_examples=400, deadline=None)
@given(
    st.one_of(st.text(max_size=200), JSON.map(json.dumps), MESSAGES.map(json.dumps), st.binary(max_size=50), HOSTILE)
)
def test_parser_refuses_with_protocol_error_only(text):
    try:
        msg = parse_message(text)
        if msg["type"] == "answer":
            target, vacuum, _ = parse_answer(msg, load_robot().workspace)
            assert all(lo <= v <= hi for v, lo, hi in zip(target, load_robot().workspace.lo, load_robot().workspace.hi))
            assert isinstance(vacuum, bool)
        elif msg["type"] == "hello":
            parse_hello(msg)
            assert msg.get("protocol") == 1 and type(msg.get("protocol")) is int
    except ProtocolError as exc:
        assert str(exc) and len(str(exc)) <= MAX_REASON and exc.code in REFUSALS


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(MESSAGES.map(json.dumps), st.text(max_size=50), HOSTILE), max_size=10))
def test_broker_never_raises_and_nothing_is_answered_without_a_request(messages):
    broker = AnnotationBroker(load_robot().workspace)
    sent: list[dict] = []
    client = broker.attach(sent.append)
    for text in messages:
        broker.receive(client, text)
    assert broker.stats.answered == 0 and broker.stats.skipped == 0
    assert set(broker.stats.refused) <= set(REFUSALS) and "internal" not in broker.stats.refused
    assert not any(m["type"] == "ack" and m["for"] in ("answer", "claim", "skip") and m["accepted"] for m in sent)
    assert sum(m["type"] == "ack" for m in sent) == len(messages)  # every message got its one reply
