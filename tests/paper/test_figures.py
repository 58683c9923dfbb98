"""The paper-figure experiments at smoke scale: PNGs, figure.json round trip, metric keys and sane values; the
original's finger voxels on a scripted path; reproducibility; resuming a figure cut short."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import envs  # noqa: F401
from eval.paper.figures import FIGURES, FigureResult, budget_for, obstacle_optimum
from eval.paper.figures.exploration import VOXEL_CORNERS, original_voxel_occupancy

SMOKE = budget_for("smoke")

EXPECTED_METRICS = {
    "obstacle_generalisation": {"box", "optimum", "standing_still", "random_mean", "methods", "paper", "seeds"},
    "plan_diversity": {"horizons", "goal_energy", "plans_per_horizon", "seeds"},
    "reacher_directions": {"cases", "horizon", "reach_tolerance", "seeds"},
    "maze_exploration": {"agents", "free_cells", "timesteps", "seeds"},
    "frontier_exploration": {"agents", "free_cells", "timesteps", "seeds"},
    "sawyer_exploration": {"agents", "max_random_occupancy", "normaliser", "seeds"},
    "energy_maps": {"envs", "checkpoints", "timesteps", "seeds"},
}


@pytest.fixture(scope="module")
def figures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[FigureResult, Path]]:
    """Every experiment run once at smoke scale (seed 0; two seeds for the Sawyer's normaliser over runs)."""
    runs = {}
    for name, function in FIGURES.items():
        out_dir = tmp_path_factory.mktemp(name)
        seeds = [0, 1] if name == "sawyer_exploration" else [0]
        runs[name] = (function(out_dir, seeds=seeds, scale="smoke"), out_dir)
    return runs


def test_the_registry_holds_the_six_paper_figures_and_the_frontier_coverage():
    assert set(FIGURES) == set(EXPECTED_METRICS)


@pytest.mark.parametrize("name", sorted(EXPECTED_METRICS))
def test_each_figure_writes_pngs_and_a_figure_json_that_round_trips(figures, name):
    result, out_dir = figures[name]
    assert result.name == name
    assert result.pngs
    for png in result.pngs:
        assert png.parent == out_dir and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    loaded = FigureResult.load(out_dir / "figure.json")
    assert loaded == result
    json.dumps(result.metrics, allow_nan=False)  # JSON-serialisable as returned, no NaN
    assert EXPECTED_METRICS[name] <= set(result.metrics)
    assert result.table_md is not None and result.table_md.startswith("| ")
    assert result.command.startswith("ebm-eval --experiment ") and "--scale smoke" in result.command


def test_obstacle_scores_are_bounded_by_the_optimum_and_the_worst_case(figures):
    metrics = figures["obstacle_generalisation"][0].metrics
    assert set(metrics["methods"]) == {"ebm_box_energy", "ebm_no_box_energy", "action_ff", "action_ff_box_model"}
    assert -10.0 < metrics["optimum"] < -4.5  # a detour around the box costs more than the open map's -4.5
    for method in metrics["methods"].values():
        # 100 steps at most, each at L1 <= 2 from the goal; nobody beats the lattice optimum by more than its grid.
        assert -200.0 <= method["mean"] <= metrics["optimum"] + 0.5
        assert 0.0 <= method["success_rate"] <= 1.0
    assert metrics["standing_still"] == pytest.approx(-100.0)
    assert metrics["paper"] == {"ebm": -61.94, "action_ff": -81.24}


def test_obstacle_optimum_is_the_open_map_optimum_when_the_box_is_out_of_the_way():
    assert obstacle_optimum((0.6, -0.9, 0.9, -0.6)) == pytest.approx(-4.5)
    with pytest.raises(ValueError, match="obstacle"):
        obstacle_optimum((0.1, 0.1, 0.5, 0.5))  # the authors' box touches the goal


def test_plan_diversity_measures_are_sane(figures):
    horizons = figures["plan_diversity"][0].metrics["horizons"]
    assert set(horizons) == {str(h) for h in SMOKE.diversity_horizons}
    for record in horizons.values():
        assert record["envelope_area"]["mean"] > 0.0
        assert record["lateral_deviation"]["mean"] >= 0.0 and record["goal_distance"]["mean"] >= 0.0
        assert 0.0 <= record["feasible_fraction"]["mean"] <= 1.0


def test_reacher_direction_fractions_are_sane(figures):
    cases = figures["reacher_directions"][0].metrics["cases"]
    assert set(cases) == {"opposite", "env_goal"}
    for case in cases.values():
        ccw, cw = case["ccw_fraction"]["mean"], case["cw_fraction"]["mean"]
        assert 0.0 <= ccw <= 1.0 and 0.0 <= cw <= 1.0 and ccw + cw <= 1.0
        assert 0.0 <= case["executed_agreement"]["mean"] <= 1.0
        assert case["both_directions"] == (ccw > 0 and cw > 0)


@pytest.mark.parametrize("name, explorer", [("maze_exploration", "ebm"), ("frontier_exploration", "ebm_frontier")])
def test_maze_coverage_is_a_fraction_that_only_grows(figures, name, explorer):
    metrics = figures[name][0].metrics
    assert set(metrics["agents"]) == {explorer, "random"}
    for record in metrics["agents"].values():
        assert 0.0 < record["coverage"]["mean"] <= 1.0
        assert 0.0 < record["coverage_of_free"]["mean"] <= 1.0
        curve = record["curve"]
        assert curve["timesteps"][-1] == SMOKE.maze_timesteps
        assert np.all(np.diff(curve["mean"]) >= 0) and curve["mean"][-1] == record["coverage"]["mean"]
    assert 0 < metrics["free_cells"] < 400


def test_sawyer_occupancy_is_normalised_by_the_best_random_run(figures):
    metrics = figures["sawyer_exploration"][0].metrics
    agents = metrics["agents"]
    assert set(agents) == {"ebm", "random_uniform", "random_joint_targets"}
    assert metrics["normaliser"] == metrics["max_random_occupancy"] + 5
    best_random = max(max(agents[a]["occupancy"]["per_seed"]) for a in ("random_uniform", "random_joint_targets"))
    assert metrics["max_random_occupancy"] == best_random
    for name, record in agents.items():
        assert 1 <= record["occupancy"]["mean"] <= 1000
        assert np.all(np.diff(record["curve"]["mean"]) >= 0)
        if name != "ebm":
            assert record["normalised_percent"]["mean"] < 100.0
            assert record["curve"]["timesteps"][-1] == SMOKE.sawyer_random_timesteps
            assert record["occupancy_at_ebm_budget"]["mean"] <= record["occupancy"]["mean"]
        at_budget = record["occupancy_at_ebm_budget"]
        assert len(at_budget["per_seed"]) == len(metrics["seeds"])  # the claim's interval needs them
        assert at_budget["mean"] == pytest.approx(np.mean(at_budget["per_seed"]))


def test_energy_maps_snapshot_both_envs_at_the_checkpoints(figures):
    metrics = figures["energy_maps"][0].metrics
    assert set(metrics["envs"]) == {"particle", "maze"}
    for record in metrics["envs"].values():
        assert [s["timestep"] for s in record["snapshots"]] == metrics["checkpoints"]
        assert len(record["snapshots"]) == SMOKE.energy_snapshots
        for snapshot in record["snapshots"]:
            assert 0.0 < snapshot["coverage"]["mean"] <= 1.0
        assert record["explored_energy_change"]["mean"] >= 0.0


def test_original_voxel_occupancy_on_a_scripted_finger_path():
    centre = VOXEL_CORNERS[0] + 0.1  # -0.9, inside the first voxel on y and z
    inside = [(corner + 0.1, centre, centre) for corner in VOXEL_CORNERS]  # one point in each of 10 voxels along x
    repeat = [(corner + 0.05, centre, centre) for corner in VOXEL_CORNERS[:3]]  # the same voxels again
    gaps = [(corner + 0.21, centre, centre) for corner in VOXEL_CORNERS[:-1]]  # between voxels: 0.2 < offset < 0.222
    faces = [(VOXEL_CORNERS[4], centre, centre), (VOXEL_CORNERS[4] + 0.2, centre, centre)]  # strictly inside only
    outside = [(-1.5, centre, centre), (0.0, 2.0, 0.0)]
    assert original_voxel_occupancy(np.array(inside + repeat + gaps + faces + outside)) == 10
    assert original_voxel_occupancy(np.array(gaps + faces + outside)) == 0
    assert original_voxel_occupancy(np.zeros((0, 3))) == 0


def test_a_figure_is_reproducible_from_its_seed(tmp_path):
    first = FIGURES["plan_diversity"](tmp_path / "a", seeds=[3], scale="smoke")
    second = FIGURES["plan_diversity"](tmp_path / "b", seeds=[3], scale="smoke")
    assert first.metrics == second.metrics


def test_bad_scale_and_seeds_are_refused(tmp_path):
    with pytest.raises(ValueError, match="scale"):
        FIGURES["plan_diversity"](tmp_path, seeds=[0], scale="huge")
    with pytest.raises(ValueError, match="seeds"):
        FIGURES["plan_diversity"](tmp_path, seeds=[], scale="smoke")


def test_figure_result_stores_png_paths_relative_to_its_folder_and_plain_json_numbers(tmp_path):
    result = FigureResult("x", [tmp_path / "a.png"], {"v": np.float32(1.5), "n": np.int64(2), "bad": np.nan}, None, "c")
    path = result.save(tmp_path)
    assert json.loads(path.read_text())["pngs"] == ["a.png"]
    loaded = FigureResult.load(path)
    assert loaded.pngs == [tmp_path / "a.png"] and loaded.metrics == {"v": 1.5, "n": 2, "bad": None}


def test_a_finished_seed_is_kept_and_read_back_instead_of_computed_again(tmp_path, capsys):
    from eval.paper.figures.common import SEED_FOLDER, seed_result

    calls = []

    def compute():
        calls.append(1)
        return {"scores": np.array([-1.5, -2.25]), "ok": np.bool_(True)}

    first = seed_result(tmp_path, "demo", 3, compute, digest="d1")
    assert capsys.readouterr().err.startswith("figure demo: seed 3 finished in ")  # a long figure says it is alive
    again = seed_result(tmp_path, "demo", 3, compute, digest="d1")
    assert capsys.readouterr().err == ""  # read back, not computed
    assert first == again == {"scores": [-1.5, -2.25], "ok": True} and len(calls) == 1
    assert (tmp_path / SEED_FOLDER / "demo_seed3.json").exists()
    seed_result(tmp_path, "demo", 3, compute, digest="other defaults")  # made with other defaults: computed again
    (tmp_path / SEED_FOLDER / "demo_seed4.json").write_text("{not json")  # a torn file: computed again
    seed_result(tmp_path, "demo", 4, compute, digest="d1")
    assert len(calls) == 3


def test_an_obstacle_figure_cut_short_resumes_with_the_seeds_it_finished(tmp_path, monkeypatch):
    import eval.paper.figures.obstacle as obstacle

    full = obstacle.obstacle_generalisation(tmp_path / "full", seeds=[0, 1], scale="smoke")
    real_build, built = obstacle.build_ebm, []

    def build_then_die_on_seed_1(env, seed, budget, **kwargs):
        built.append(seed)
        if seed == 1:
            raise KeyboardInterrupt  # the session ends while seed 1 trains
        return real_build(env, seed, budget, **kwargs)

    monkeypatch.setattr(obstacle, "build_ebm", build_then_die_on_seed_1)
    with pytest.raises(KeyboardInterrupt):
        obstacle.obstacle_generalisation(tmp_path / "cut", seeds=[0, 1], scale="smoke")

    def build(env, seed, budget, **kwargs):
        built.append(seed)
        return real_build(env, seed, budget, **kwargs)

    monkeypatch.setattr(obstacle, "build_ebm", build)
    resumed = obstacle.obstacle_generalisation(tmp_path / "cut", seeds=[0, 1], scale="smoke")
    assert built == [0, 1, 1]  # seed 0 was not trained again
    assert resumed.metrics["methods"] == full.metrics["methods"]  # the same numbers as a figure run in one go


def test_a_rerun_of_the_sawyer_exploration_reads_its_finished_seeds_back(tmp_path, monkeypatch):
    import eval.paper.figures.exploration as exploration

    first = exploration.sawyer_exploration(tmp_path, seeds=[0], scale="smoke")

    def no_training(*args, **kwargs):
        raise AssertionError("a finished seed was trained again")

    monkeypatch.setattr(exploration, "build_ebm", no_training)
    again = exploration.sawyer_exploration(tmp_path, seeds=[0], scale="smoke")
    assert again.metrics == first.metrics


def test_energy_maps_cut_short_resume_with_the_runs_they_finished(tmp_path, monkeypatch):
    import eval.paper.figures.energy as energy

    full = energy.energy_maps(tmp_path / "full", seeds=[0, 1], scale="smoke")
    real_build, built = energy.build_ebm, []

    def build(env, seed, budget, **kwargs):
        built.append((env.spec.id, seed))
        if len(built) == 3:
            raise KeyboardInterrupt  # cut short while the maze's first run trains
        return real_build(env, seed, budget, **kwargs)

    monkeypatch.setattr(energy, "build_ebm", build)
    with pytest.raises(KeyboardInterrupt):
        energy.energy_maps(tmp_path / "cut", seeds=[0, 1], scale="smoke")
    built.clear()
    monkeypatch.setattr(
        energy,
        "build_ebm",
        lambda env, seed, budget, **kw: built.append((env.spec.id, seed)) or real_build(env, seed, budget, **kw),
    )
    resumed = energy.energy_maps(tmp_path / "cut", seeds=[0, 1], scale="smoke")
    assert built == [("ebm/Maze-v0", 0), ("ebm/Maze-v0", 1)]  # the particle's two runs were kept
    assert resumed.metrics == full.metrics
    assert all(png.exists() for png in resumed.pngs)
