"""A learned effect judged beside the default imperfections' look-alikes refitted on the
held-out flight (issue 26, "steps7"; omavctl/diagnose/learned_beside.py), and any effect,
not only a lag or delay, judged there when the joint selection took only look-alikes
(omavctl/diagnose/timing_beside.py)."""

from __future__ import annotations

import numpy as np
import pytest

from omavctl.diagnose.claim_text import learned_claim_text
from omavctl.diagnose.claims import LARGE_CUT, large_cut_step, learned_claim
from omavctl.diagnose.joint import MIN_HAC_T, MIN_SHARE
from omavctl.diagnose.learned_beside import learned_beside_look_alikes
from omavctl.diagnose.timing_beside import timing_beside_look_alikes
from tests.conftest import rebuilt
from tests.test_diagnose_joint import DT, FLOOR, _case

DRAG = np.array([0.05, 0.04, 0.03])
COM = np.array([0.06, -0.05, 0.04])


def _drag_beside_offset(drag: np.ndarray | None, com: np.ndarray = COM, seed: int = 0):
    """A drag learned on the fit flight, held out on a steps flight (large in 2 of the
    10 blocks' transitions, 0.15 of that between them), beside a CoM offset (a thrust
    spread every rotorcraft has) that the held-out error holds at ``com``."""
    truth = {"rotational_drag": drag, "com_offset": com, "rotor_interference": None}
    model, physics, regs, blocks = _case(truth, seed=seed)
    reg = regs["rotational_drag"]
    held = reg * np.where(blocks % 5 == 0, 1.0, 0.15)[:, None, None]
    if drag is not None:
        physics = physics + (held - reg) @ drag
    return model, physics, {**regs, "rotational_drag": held}, blocks


def _entry(name: str = "rotational_drag") -> dict:
    return {
        "name": name,
        "missing": True,
        "explained_variance_per_axis": {"x": 0.6, "y": 0.5, "z": 0.4},
        "estimate": {"D_ci95": [[0.04, 0.06], [0.03, 0.05], [0.02, 0.04]]},
    }


def test_a_learned_drag_under_a_large_offset_is_claimed_beside_the_look_alikes():
    """Against the whole held-out error (the offset in it) the drag removes under half:
    no claim; against what the look-alikes leave at their held-out fit it removes nearly
    all, every block better, with the fit flight's estimate."""
    model, physics, regs, blocks = _drag_beside_offset(DRAG)
    drag = regs["rotational_drag"]
    whole = large_cut_step(model, "rotational_drag", physics, drag, blocks, FLOOR)
    assert whole is None
    assert learned_claim([_entry()], [], model, physics, regs, blocks, FLOOR) is None
    found = learned_beside_look_alikes([_entry()], [], model, physics, regs, blocks, FLOOR)
    assert found is not None
    step, entry = found
    assert step.name == entry["name"] == "rotational_drag"
    assert step.share >= 0.9 > LARGE_CUT and step.log_ratio_t >= MIN_HAC_T
    assert (step.blocks_better, step.blocks) == (10, 10)
    assert step.share_of_total < step.share  # the offset's part is not its share
    assert step.theta == pytest.approx(DRAG, rel=0.15)  # the offset in its targets


def test_no_drag_no_claim_and_a_look_alike_is_never_claimed_here():
    model, physics, regs, blocks = _drag_beside_offset(None)
    assert learned_beside_look_alikes([_entry()], [], model, physics, regs, blocks, FLOOR) is None
    model, physics, regs, blocks = _drag_beside_offset(DRAG)
    offset = {**_entry("com_offset"), "estimate": {"r_ci95": [[0.05, 0.07]] * 3}}
    found = learned_beside_look_alikes([offset], [], model, physics, regs, blocks, FLOOR)
    assert found is None
    wide = {**_entry(), "estimate": {"D_ci95": [[-0.01, 0.03]] * 3}}  # holds its null
    assert learned_beside_look_alikes([wide], [], model, physics, regs, blocks, FLOOR) is None


def _inertia_beside_offset(scale: np.ndarray | None, shrink: float = 0.4, seed: int = 3):
    """An inertia error under look-alikes the GP absorbed on the fit flight (its targets
    hold them at ``shrink`` of their held-out size, as on a steps fit flight)."""
    alikes = {"com_offset": COM, "rotor_interference": np.array([0.3, 0.1])}
    model, physics, regs, blocks = _case({**alikes, "inertia_error": scale}, seed=seed)
    train = model.train_regressors
    targets = model.targets - (1 - shrink) * sum(train[n] @ t for n, t in alikes.items())
    return rebuilt(model, targets=targets, train_regressors=train), physics, regs, blocks


def test_an_inertia_error_is_judged_beside_the_look_alikes_when_only_they_were_taken():
    model, physics, regs, blocks = _inertia_beside_offset(np.array([0.3, 0.3, -0.3]))
    (step,) = timing_beside_look_alikes([], model, physics, regs, ["com_offset"], FLOOR, blocks, DT)
    assert step.name == "inertia_error" and step.share >= MIN_SHARE
    assert step.timing_rivals == []  # not a lag or delay: no timing rival gives way to it
    # once a further effect was taken, it is not judged here
    got = timing_beside_look_alikes([], model, physics, regs, ["inertia_error"], FLOOR, blocks, DT)
    assert got == []
    model, physics, regs, blocks = _inertia_beside_offset(None)
    assert (
        timing_beside_look_alikes([], model, physics, regs, ["com_offset"], FLOOR, blocks, DT) == []
    )


def test_the_verdict_says_what_a_share_beside_the_look_alikes_is_of():
    model, physics, regs, blocks = _drag_beside_offset(DRAG)
    found = learned_beside_look_alikes([_entry()], [], model, physics, regs, blocks, FLOOR)
    assert found is not None
    step = found[0].to_json()
    assert step["beside_look_alikes"] is True
    diag = {"missing": [], "learned_claims": ["rotational_drag"], "learned_steps": [step]}
    text = learned_claim_text(diag, "on the held-out flight")
    total = f"{100 * step['share_of_total']:.0f} %"
    assert (
        " That share is of what com_offset and rotor_interference, the look-alikes of every "
        "rotorcraft's imperfections, leave at their least-squares fit on this flight; of "
        f"the whole physics-only error it removes {total}."
    ) in text
    del step["beside_look_alikes"]  # a share of the whole error says nothing more
    assert "That share is of" not in learned_claim_text(diag, "on the held-out flight")


# ------------------------------------------- the look-alikes the GP learned, together
INTERFERENCE = np.array([0.6, 0.5])


def _alike_entry(name: str, ci: list | None = None) -> dict:
    key = {"com_offset": "r_ci95", "rotor_interference": "rotor_rotor_ci95"}[name]
    estimate = {key: ci if ci is not None else [[0.3, 0.9]] * (3 if name == "com_offset" else 1)}
    if name == "rotor_interference":
        estimate["rotor_arm_ci95"] = [[-0.1, 0.9]]
    return {"name": name, "missing": True, "explained_variance": 0.5,
            "explained_variance_per_axis": None, "estimate": estimate}  # fmt: skip


def _alikes_learned(interference: np.ndarray | None, seed: int = 4):
    """A larger rotor interference beside the offset of the thrust spread, learned by
    the GP on the fit flight; the held-out error holds both."""
    truth = {"com_offset": COM, "rotor_interference": interference}
    return _case(truth, seed=seed)


def test_the_look_alikes_the_gp_learned_are_claimed_together() -> None:
    from omavctl.diagnose.learned_alikes import learned_look_alikes

    model, physics, regs, blocks = _alikes_learned(INTERFERENCE)
    pool = [_alike_entry("rotor_interference"), _alike_entry("com_offset", [[-0.1, 0.2]] * 3)]
    found = learned_look_alikes(pool, model, physics, regs, blocks, FLOOR)
    assert found is not None
    step, entry = found
    # the pinned one leads, the other is claimed with it
    assert (step.name, step.also, entry["name"]) == (
        "rotor_interference", ["com_offset"], "rotor_interference"
    )  # fmt: skip
    assert step.share >= 0.9 and step.log_ratio_t >= MIN_HAC_T
    assert step.theta == pytest.approx(INTERFERENCE, rel=0.15)
    assert step.to_json()["jointly_with"] == ["com_offset"]
    diag = {"missing": [], "learned_claims": ["rotor_interference", "com_offset"],
            "learned_steps": [{**entry, **step.to_json()}]}  # fmt: skip
    text = learned_claim_text(diag, "on held-out data")
    assert text.startswith(
        "Learned by the GP, not yet in the physics: rotor_interference with com_offset, the "
        "look-alikes of every rotorcraft's imperfections"
    )
    assert "estimated together from the fit flight by least squares, they remove" in text


def test_look_alikes_are_not_claimed_together_alone_unpinned_or_absent() -> None:
    from omavctl.diagnose.learned_alikes import learned_look_alikes

    model, physics, regs, blocks = _alikes_learned(INTERFERENCE)
    one = [_alike_entry("rotor_interference")]  # one look-alike: the tests of one decide
    assert learned_look_alikes(one, model, physics, regs, blocks, FLOOR) is None
    unpinned = [_alike_entry("rotor_interference", [[0.0, 0.9]]),
                _alike_entry("com_offset", [[-0.1, 0.2]] * 3)]  # fmt: skip
    assert learned_look_alikes(unpinned, model, physics, regs, blocks, FLOOR) is None
    model, physics, regs, blocks = _case({"com_offset": None, "rotor_interference": None})
    both = [_alike_entry("rotor_interference"), _alike_entry("com_offset")]
    assert learned_look_alikes(both, model, physics, regs, blocks, FLOOR) is None
