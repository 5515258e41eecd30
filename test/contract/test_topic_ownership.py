"""The ROS-free half of "only the cell acts on the cell" (winder.contract.trust):
every topic a node acts on has one owning role, the roles' graph signatures
tell them apart, and refused messages are counted per sender and topic."""

from __future__ import annotations

from winder.contract import topics
from winder.contract.trust import OWNERS, SIGNS, Intruders


def test_every_topic_a_node_acts_on_has_an_owner_that_publishes_it() -> None:
    acted_on = {
        topics.TOPIC_JOB, topics.TOPIC_STEPS, topics.TOPIC_STEP_TIMES, topics.TOPIC_CONTROL,
        topics.TOPIC_PATH, topics.TOPIC_PROFILE_CONFIG, topics.TOPIC_SIM_CONFIG,
        topics.TOPIC_PROGRESS, topics.TOPIC_STATE,
    }  # fmt: skip
    assert set(OWNERS) == acted_on
    assert set(OWNERS.values()) == set(SIGNS) == set(topics.ROLES)


def test_no_role_signature_is_contained_in_another() -> None:
    # a node that plays one role never looks like it plays another by its endpoints alone
    for a, (pub_a, sub_a) in SIGNS.items():
        for b, (pub_b, sub_b) in SIGNS.items():
            if a != b:
                assert not (set(pub_a) <= set(pub_b) and set(sub_a) <= set(sub_b)), (a, b)


def test_intruders_are_counted_per_sender_and_reported_once() -> None:
    seen = Intruders()
    firsts = [
        seen.count("/c1/intruder", "/c1/winder/control"),
        seen.count("/c1/intruder", "/c1/winder/control"),
        seen.count("/c1/intruder", "/c1/winder/job"),
        seen.count("/player", "/c1/winder/step_times"),
    ]
    assert firsts == [True, False, False, True]
    assert seen.total == 4
    assert seen.senders() == ["/c1/intruder", "/player"]
    assert seen.summary() == (
        "/c1/intruder (2 on /c1/winder/control, 1 on /c1/winder/job); /player (1 on /c1/winder/step_times)"
    )
    assert Intruders().summary() == "" and Intruders().total == 0
