"""The roulette-depth model (render/scene/roulette.py) against Chandrasekhar's table and a Monte Carlo of the
collisions after which a half-space sends its light back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from render.scene import roulette
from render.scene.optics import derive_snow, load_preset, reduce


def nadir_return_by_collisions(walkers: int, max_collisions: int, seed: int) -> np.ndarray:
    """Light of a conservative isotropic half-space lit along the normal and seen along it, by the collision
    it leaves after: element k is the mean of e^(-z) over the walks' k-th collisions at depth z (mean free
    paths), the chance of leaving toward the nadir view unscattered."""
    rng = np.random.default_rng(seed)
    depth = rng.exponential(size=walkers)
    by_collision = np.zeros(max_collisions + 1)
    for k in range(1, max_collisions + 1):
        by_collision[k] = np.exp(-depth).sum()
        depth = depth + rng.uniform(-1.0, 1.0, size=depth.size) * rng.exponential(size=depth.size)
        depth = depth[depth > 0.0]
    return by_collision / walkers


def test_h_function_matches_chandrasekhars_table(validation):
    validation.record(
        "roulette model: H(1) of a conservative isotropic half-space",
        roulette.h_function_at_one(1.0),
        reference=2.9078,
        tolerance="±2 × 10⁻⁴",
        against="Chandrasekhar 1960, Table XI",
    )
    assert roulette.h_function_at_one(1.0) == pytest.approx(2.9078, abs=2e-4)  # Chandrasekhar 1960, Table XI
    # Below the conservative case H(1) falls, and the normal reflection with it.
    assert roulette.h_function_at_one(0.9) < roulette.h_function_at_one(0.999) < roulette.h_function_at_one(1.0)
    with pytest.raises(ValueError, match="albedo"):
        roulette.h_function_at_one(1.5)


@pytest.mark.parametrize("albedo", [0.995, 0.999])
def test_late_share_matches_a_monte_carlo_of_the_half_space(albedo, validation):
    walks = nadir_return_by_collisions(200_000, 2500, seed=3)
    light = walks * albedo ** np.arange(walks.size)
    # The totals' ratio between two albedos is the reflection function's (both exact).
    other = walks * 0.99 ** np.arange(walks.size)
    assert other.sum() / light.sum() == pytest.approx(
        roulette.normal_reflection(0.99) / roulette.normal_reflection(albedo), rel=0.01
    )
    # The walks stop at 2500 collisions: compare the shares of what they hold, past each count.
    held = 1.0 - roulette.late_share(walks.size - 1, albedo)
    for collisions in (100, 300, 1000):
        simulated = light[collisions + 1 :].sum() / light.sum()
        model = (roulette.late_share(collisions, albedo) - (1.0 - held)) / held
        print(f"albedo {albedo}, past {collisions}: walks {simulated:.5f}, model {model:.5f}")
        validation.record(
            f"roulette model, albedo {albedo}: share of the light returned after {collisions} collisions",
            model,
            reference=simulated,
            tolerance="±6 %",
            against="a Monte Carlo of 200 000 walks in the half-space",
        )
        assert model == pytest.approx(simulated, rel=0.06)
        # The asymptotic form leaves the early walks' 1/n correction out, which only makes it larger: safe.
        assert model >= 0.97 * simulated


def test_reach_and_missed_share_follow_the_cap_and_the_samples():
    assert roulette.reach(100, 0.95, 1) == 100
    assert roulette.reach(100, 0.95, 64) == pytest.approx(100 + math.log(64) / -math.log(0.95))
    channel = roulette.ReducedChannel(albedo=0.9999, collisions_per_step=1.0)
    shallow = roulette.missed_share(channel, 200, 0.95, 64)
    deeper = roulette.missed_share(channel, 2000, 0.95, 64)
    assert shallow > deeper > roulette.missed_share(channel, 2000, 0.999, 64)
    # g > 0: a reduced collision stands for 1/(1 - g) collisions, so the same depth reaches fewer of them.
    forward = roulette.ReducedChannel(albedo=0.9999, collisions_per_step=1.0 / (1.0 - 0.86))
    assert roulette.missed_share(forward, 2000, 0.95, 64) > deeper
    assert roulette.missed_share(roulette.ReducedChannel(0.0, 1.0), 5, 0.95, 64) == 0.0


def test_auto_depth_meets_its_target_and_is_the_smallest_to_two_figures():
    optics = reduce(load_preset("fresh_snow"), "isotropic_reduced")
    media = {"snow": roulette.reduced_channels(optics.sigma_s, optics.sigma_a, optics.g)}
    chosen = roulette.auto_rr_depth(media, samples=64)
    assert chosen.missed <= roulette.AUTO_MISSED_SHARE
    assert chosen.medium == "snow (B)"  # blue is absorbed least, so it returns latest
    step = 10 ** (len(str(chosen.rr_depth)) - 2)
    earlier, _ = roulette.worst_missed(media, chosen.rr_depth - step, roulette.MITSUBA_SURVIVAL_CAP, 64)
    assert earlier > roulette.AUTO_MISSED_SHARE * 0.9  # one step shallower is (about) over the target


def test_finer_grains_and_full_phase_functions_need_deeper_roulette():
    def depth(optics) -> int:
        media = {"snow": roulette.reduced_channels(optics.sigma_s, optics.sigma_a, optics.g)}
        return roulette.auto_rr_depth(media, samples=64).rr_depth

    fine, coarse = (reduce(derive_snow(550.0, optical_radius=r), "isotropic_reduced") for r in (0.0002, 0.003))
    assert depth(fine) > 3 * depth(coarse)
    firn = load_preset("penitente_firn")
    assert depth(reduce(firn, "full")) > 4 * depth(reduce(firn, "isotropic_reduced"))


def test_negative_coefficients_are_refused():
    with pytest.raises(ValueError, match="sigma_s"):
        roulette.reduced_channels([-1.0, 1.0, 1.0], [0.1] * 3, [0.0] * 3)
