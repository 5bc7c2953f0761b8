"""The workflow the verdict asks for, judged on trajectories the model has not seen
(benchmarks/generalise.py, pinned): fit on two flights with the named effects, fly two
others. In its own file, apart from test_generalise.py's module fixture, so that
`make test`'s two workers (one test file each, ``--dist loadfile``) can run the two
longest pieces of the generalisation tests side by side.
"""

from __future__ import annotations

import numpy as np


def test_two_flights_with_the_named_effects_hold_on_two_other_trajectories(tmp_path):
    """The workflow the verdict asks for: fit on two different flights (figure-8 and
    wobble) with the effects the diagnosis names, then fly two trajectories neither
    of them is (a faster, larger figure-8 and another wobble). Motor lag, a 1 kHz
    controller logged at 100 Hz: the model beats physics on both and its band is
    honest on both as issue 26 asks: 2-sigma coverage >= 0.85 on every axis, and <= 0.99
    on the samples inside the fit flights' inputs (wider than needed beyond them is
    accepted; docs/generalisation.md: 77 of 84 axis-directions of this kind in
    0.85-0.99, 2 below). The robust (HAC) standard errors, counted in the band as
    independent ``X se`` terms everywhere, had widened it to 0.997-0.999 on fig8fast
    and the upper bound was relaxed to 0.995 on wobble7 alone; the parameter term is
    now that of a GP with explicit basis functions inside the fit inputs
    (docs/generalisation.md, "The band inside the fit flight's inputs"). Measured
    with the held-out floor only beyond the fit inputs and the band's growth there
    (docs/intervals.md): fig8fast 0.982 / 0.994 / 0.969, inside 0.970 / 0.989 / 0.963
    (48 % of it outside); wobble7 0.967 / 0.932 / 0.965 (all inside). Before: fig8fast
    0.987 / 0.994 / 0.928, inside 0.981 / 0.989 / 0.972; wobble7 0.981 / 0.932 / 0.982.
    At abbc9f2: fig8fast 0.970 / 0.987 / 0.963, inside 0.956 / 0.980 / 0.960 (46 %
    outside); wobble7 0.972 / 0.940 / 0.963. With the band inside following the GP's
    distance from its data (session 21, docs/intervals.md) z moves: fig8fast 0.955
    (inside 0.947), wobble7 0.950."""
    from benchmarks.generalise import known_effects, run_two_flights

    for o in run_two_flights(
        tmp_path, "motor_lag", "1kHz-sampled", effects=known_effects("motor_lag")
    ):
        print(
            o.held_out,
            "ratio",
            o.ratio.round(2),
            "coverage",
            o.coverage.round(3),
            "inside",
            o.coverage_inside.round(3),
            "outside share",
            round(o.outside, 2),
        )
        assert np.all(o.ratio <= 0.8), o.ratio
        assert np.all(o.coverage >= 0.85), o.coverage
        assert np.all(o.coverage_inside <= 0.99), o.coverage_inside
        # nothing missing but the thrust spread's look-alike: the simulator's 3 % rotor
        # thrust spread shifts where the thrust acts, which the joint selection may
        # name as com_offset (a default imperfection, docs/scorecard.md: not invented)
        assert set(o.missing) <= {"com_offset"}, o.missing
