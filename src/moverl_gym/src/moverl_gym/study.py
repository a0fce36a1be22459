"""The experiment study (paper Figs. 6 and 7), ROS-free: run names, reading run folders, smoothing,
aggregation over seeds, the figures and the results table. Used by scripts/study.py; tested on synthetic CSVs.

A run folder is what scripts/train.py writes: <out>/<algo>_<EnvName>_<on|off>_s<seed>/ with episodes.csv,
summary.json (only once the run finished) and config.yaml.
"""

from __future__ import annotations

import csv
import json
import math
import re
import textwrap
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SCENARIOS = ("table", "human", "case")
SHIELD_COLORS = {"on": "tab:blue", "off": "tab:red"}
SHIELD_LABELS = {"on": "shield on", "off": "shield off (no checks)"}
_BOOLS = {"true": 1.0, "false": 0.0}
RUN_RE = re.compile(r"^(?P<algo>[a-z0-9]+)_(?P<env>[A-Za-z0-9]+-v\d+)_(?P<shield>on|off)_s(?P<seed>-?\d+)$")


def env_id(scenario: str, obs: str = "") -> str:
    """'table' -> 'MoveRL/PandaReachTable-v0' (obs 'EE' for the end-effector observation variant)."""
    return f"MoveRL/PandaReach{scenario.capitalize()}{obs}-v0"


def scenario_of(env: str) -> str:
    """'MoveRL/PandaReachCaseEE-v0' or 'PandaReachCase-v0' -> 'case'."""
    m = re.search(r"PandaReach([A-Z][a-z]+)", env)
    if not m:
        raise ValueError(f"not a MoveRL reach env id: {env!r}")
    return m.group(1).lower()


def run_name(algo: str, env: str, shield: str, seed: int) -> str:
    """The folder name train.py uses: ppo_PandaReachTable-v0_on_s0."""
    return f"{algo}_{env.split('/')[-1]}_{shield}_s{seed}"


@dataclass
class Run:
    """One training run read from disk. episodes: column name -> float array (one entry per finished episode)."""

    path: Path
    algo: str
    scenario: str
    shield: str
    seed: int
    episodes: dict = field(default_factory=dict)
    summary: dict | None = None
    config: dict = field(default_factory=dict)

    @property
    def finished(self) -> bool:
        return self.summary is not None

    @property
    def n_episodes(self) -> int:
        return len(self.episodes.get("episode", []))


def read_episodes(path: Path) -> dict:
    """episodes.csv -> {column: float array}; an empty or header-only file gives empty arrays."""
    path = Path(path)
    if not path.exists():
        return {}
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        with open(path, newline="") as f:
            header = next(csv.reader(f), [])
        return {k: np.zeros(0) for k in header}
    out = {}
    for key in rows[0]:
        vals = []
        for r in rows:
            v = r.get(key)
            try:
                vals.append(float(v) if v not in (None, "") else math.nan)
            except ValueError:
                vals.append(_BOOLS.get(str(v).strip().lower(), math.nan))
        out[key] = np.asarray(vals, dtype=float)
    return out


def load_run(path: Path) -> Run | None:
    """A run folder -> Run (None if the name is not a train.py run folder)."""
    path = Path(path)
    m = RUN_RE.match(path.name)
    if not m:
        return None
    summary = None
    if (path / "summary.json").exists():
        summary = json.loads((path / "summary.json").read_text())
    config = {}
    if (path / "config.yaml").exists():
        import yaml

        config = yaml.safe_load((path / "config.yaml").read_text()) or {}
    return Run(
        path=path,
        algo=m["algo"],
        scenario=scenario_of(m["env"]),
        shield=m["shield"],
        seed=int(m["seed"]),
        episodes=read_episodes(path / "episodes.csv"),
        summary=summary,
        config=config,
    )


def load_runs(root: Path, finished_only: bool = False) -> list[Run]:
    """Every run folder directly under root, sorted by scenario (paper order), shield, seed."""
    root = Path(root)
    runs = (
        [r for r in (load_run(p) for p in sorted(root.iterdir()) if p.is_dir()) if r is not None]
        if root.exists()
        else []
    )
    if finished_only:
        runs = [r for r in runs if r.finished]
    order = {s: i for i, s in enumerate(SCENARIOS)}
    return sorted(runs, key=lambda r: (order.get(r.scenario, 99), r.scenario, r.shield != "on", r.seed))


def smooth(x, window: int) -> np.ndarray:
    """Trailing moving average with a window that grows from 1 at the start (no edge drop, same length)."""
    x = np.asarray(x, dtype=float)
    if window <= 1 or x.size == 0:
        return x.copy()
    c = np.cumsum(np.insert(x, 0, 0.0))
    idx = np.arange(1, x.size + 1)
    lo = np.maximum(idx - window, 0)
    return (c[idx] - c[lo]) / (idx - lo)


def curve_on_grid(timesteps, values, grid, window: int = 1) -> np.ndarray:
    """A per-episode quantity, smoothed over `window` episodes, as a function of env steps, sampled on grid
    (linear interpolation between episode ends; NaN outside the run's range so partial runs do not extrapolate)."""
    t = np.asarray(timesteps, dtype=float)
    v = smooth(values, window)
    grid = np.asarray(grid, dtype=float)
    out = np.full(grid.shape, np.nan)
    if t.size == 0:
        return out
    inside = (grid >= t[0]) & (grid <= t[-1])
    out[inside] = np.interp(grid[inside], t, v)
    return out


def aggregate_curves(curves) -> dict:
    """Curves (seeds x grid, NaN where a seed has no data) -> mean, std, min, max and n per grid point."""
    a = np.atleast_2d(np.asarray(curves, dtype=float))
    n = np.sum(~np.isnan(a), axis=0)
    with warnings.catch_warnings():  # all-NaN columns (no seed reached that step yet) stay NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return {
            "mean": np.nanmean(a, axis=0),
            "std": np.nanstd(a, axis=0),
            "min": np.nanmin(a, axis=0),
            "max": np.nanmax(a, axis=0),
            "n": n,
        }


def mean_std(values) -> tuple[float, float]:
    """Mean and population std of the finite values (NaN, NaN if none)."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std())


def success_last(run: Run, last: int = 200) -> float:
    """Success rate over the run's last `last` finished episodes."""
    s = run.episodes.get("success", np.zeros(0))
    return float(np.mean(s[-last:])) if s.size else math.nan


def _total(run: Run, key: str) -> int:
    v = run.episodes.get(key)
    return int(np.nansum(v)) if v is not None and v.size else 0


def summarize(runs: list[Run], last: int = 200) -> list[dict]:
    """One row per (scenario, shield) over finished runs: success over the last `last` episodes (mean, std
    over seeds), ground-truth contacts, shield interventions, wall-clock and speed."""
    rows = []
    groups: dict[tuple, list[Run]] = {}
    for r in runs:
        if r.finished:
            groups.setdefault((r.scenario, r.shield), []).append(r)
    order = {s: i for i, s in enumerate(SCENARIOS)}
    for (scenario, shield), rs in sorted(groups.items(), key=lambda kv: (order.get(kv[0][0], 99), kv[0][1] != "on")):
        succ = [success_last(r, last) for r in rs]
        contacts = [_total(r, "contacts") for r in rs]
        episodes = [r.n_episodes for r in rs]
        walls = [float(r.summary.get("wall_time", math.nan)) for r in rs]
        sps = [float(r.summary.get("steps_per_second", math.nan)) for r in rs]
        s_mean, s_std = mean_std(succ)
        w_mean, w_std = mean_std(walls)
        rows.append(
            {
                "scenario": scenario,
                "shield": shield,
                "seeds": " ".join(str(r.seed) for r in rs),
                "n_runs": len(rs),
                "success_last_mean": s_mean,
                "success_last_std": s_std,
                "success_last_per_seed": " ".join(f"{x:.3f}" for x in succ),
                "episodes_mean": float(np.mean(episodes)),
                "contacts_total": int(sum(contacts)),
                "contacts_per_run": " ".join(str(c) for c in contacts),
                "contacts_per_episode": float(sum(contacts) / max(sum(episodes), 1)),
                "runs_with_contacts": int(sum(c > 0 for c in contacts)),
                "interventions_total": sum(_total(r, "interventions") for r in rs),
                "replanned_total": sum(_total(r, "replanned") for r in rs),
                "truncated_total": sum(_total(r, "truncated") for r in rs),
                "wall_time_mean": w_mean,
                "wall_time_std": w_std,
                "wall_time_max": float(np.nanmax(walls)),
                "steps_per_second_mean": mean_std(sps)[0],
            }
        )
    return rows


def write_csv(rows: list[dict], path: Path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        if not rows:
            f.write("")
            return
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()})


def _pct(m: float, s: float) -> str:
    return "n/a" if not np.isfinite(m) else f"{100 * m:.1f} ± {100 * s:.1f} %"


def markdown_table(rows: list[dict], last: int = 200) -> str:
    """The results table (GitHub markdown)."""
    head = (
        f"| scenario | shield | runs (seeds) | success, last {last} episodes (mean ± std over seeds) | "
        "per seed | episodes per run | ground-truth contacts: total (per run) | contacts / episode | "
        "shield interventions (discarded) | replanned | truncated | wall-clock per run (s) | steps/s |"
    )
    sep = "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"
    lines = [head, sep]
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {r['shield']} | {r['n_runs']} ({r['seeds']}) | "
            f"{_pct(r['success_last_mean'], r['success_last_std'])} | {r['success_last_per_seed']} | "
            f"{r['episodes_mean']:.0f} | {r['contacts_total']} ({r['contacts_per_run']}) | "
            f"{r['contacts_per_episode']:.2f} | {r['interventions_total']} | {r['replanned_total']} | "
            f"{r['truncated_total']} | {r['wall_time_mean']:.0f} ± {r['wall_time_std']:.0f} (max "
            f"{r['wall_time_max']:.0f}) | {r['steps_per_second_mean']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def per_run_table(runs: list[Run], last: int = 200) -> str:
    """One markdown row per run (finished or not): episodes, success over the last `last`, contacts,
    interventions, wall-clock and speed (from summary.json, '-' while the run is unfinished)."""
    lines = [
        f"| run | finished | episodes | env steps | success, last {last} | contacts | interventions | "
        "replanned | wall-clock (s) | steps/s |",
        "|" + "|".join(["---"] * 10) + "|",
    ]
    for r in runs:
        ts = r.episodes.get("timesteps", np.zeros(0))
        sm = r.summary or {}
        wall = f"{sm['wall_time']:.0f}" if "wall_time" in sm else "-"
        sps = f"{sm['steps_per_second']:.0f}" if "steps_per_second" in sm else "-"
        succ = success_last(r, last)
        lines.append(
            f"| {r.path.name} | {'yes' if r.finished else 'no'} | {r.n_episodes} | "
            f"{int(ts[-1]) if ts.size else 0} | {'n/a' if not np.isfinite(succ) else f'{100 * succ:.1f} %'} | "
            f"{_total(r, 'contacts')} | {_total(r, 'interventions')} | {_total(r, 'replanned')} | "
            f"{wall} | {sps} |"
        )
    return "\n".join(lines) + "\n"


def settings_groups(runs: list[Run]) -> dict[str, list[str]]:
    """Runs grouped by their training settings (task constants and hyper-parameters from config.yaml): more than
    one group means the runs are not comparable (the env or the hyper-parameters changed between runs)."""
    groups: dict[str, list[str]] = {}
    for r in runs:
        key = json.dumps(
            {
                "task": r.config.get("task"),
                "hyperparams": r.config.get("hyperparams"),
                "n_timesteps": r.config.get("n_timesteps"),
            },
            sort_keys=True,
        )
        groups.setdefault(key, []).append(r.path.name)
    return groups


def missing_runs(root: Path, scenarios, shields, seeds, algo: str = "ppo", variant: str = "") -> list[str]:
    """Names of the planned runs without a summary.json under root (variant: the id suffix, e.g. "Goal")."""
    root = Path(root)
    return [
        run_name(algo, env_id(sc, variant), sh, sd)
        for sc in scenarios
        for sh in shields
        for sd in seeds
        if not (root / run_name(algo, env_id(sc, variant), sh, sd) / "summary.json").exists()
    ]


# -- figures ----------------------------------------------------------------------------------------------
def _grid_for(runs: list[Run], points: int = 200) -> np.ndarray:
    tmax = max(
        (float(r.episodes["timesteps"][-1]) for r in runs if r.episodes.get("timesteps", np.zeros(0)).size), default=1.0
    )
    return np.linspace(0.0, tmax, points)


def _band(ax, grid, curves, color, label, band: str = "minmax"):
    agg = aggregate_curves(curves)
    ok = agg["n"] > 0
    n_seeds = len(curves)
    ax.plot(grid[ok], agg["mean"][ok], color=color, lw=1.8, label=label)
    lo, hi = (agg["min"], agg["max"]) if band == "minmax" else (agg["mean"] - agg["std"], agg["mean"] + agg["std"])
    if n_seeds > 1:
        ax.fill_between(grid[ok], lo[ok], hi[ok], color=color, alpha=0.2, lw=0)


def _scenarios_present(runs: list[Run]) -> list[str]:
    present = {r.scenario for r in runs}
    return [s for s in SCENARIOS if s in present] + sorted(present - set(SCENARIOS))


def plot_contacts(runs: list[Run], path: Path, window: int = 20, title_suffix: str = "") -> Path:
    """Fig. 6: ground-truth contacts per episode vs env steps, shield on vs off, one panel per scenario."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [r for r in runs if r.n_episodes > 0]
    scenarios = _scenarios_present(runs) or ["(no runs)"]
    fig, axes = plt.subplots(1, len(scenarios), figsize=(max(5.2 * len(scenarios), 8.0), 4.4), squeeze=False)
    grid = _grid_for(runs)
    for ax, sc in zip(axes[0], scenarios):
        totals = []
        for shield in ("off", "on"):
            rs = [r for r in runs if r.scenario == sc and r.shield == shield]
            if not rs:
                continue
            curves = [curve_on_grid(r.episodes["timesteps"], r.episodes["contacts"], grid, window) for r in rs]
            _band(ax, grid, curves, SHIELD_COLORS[shield], SHIELD_LABELS[shield])
            totals.append(f"{shield} {sum(_total(r, 'contacts') for r in rs)} ({len(rs)} runs)")
        ax.set_title(f"{sc}\ntotal contacts: {', '.join(totals)}" if totals else sc, fontsize=10)
        ax.set_xlabel("environment steps")
        ax.grid(alpha=0.3)
        ax.set_ylim(bottom=-0.02 * max(ax.get_ylim()[1], 1.0))
    axes[0][0].set_ylabel(f"contacts per episode\n(ground truth, {window}-episode mean)")
    _finish(
        fig,
        "Fig. 6 (reproduced): ground-truth collisions (contact pairs) per episode, with and without the "
        "shield; line = mean over seeds, band = min-max" + title_suffix,
        axes,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _finish(fig, title: str, axes) -> None:
    """Wrapped title, one legend for the whole figure (no curve hidden under it), tight layout."""
    handles, labels = {}, []
    for ax in np.ravel(axes):
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in handles:
                handles[lab] = h
                labels.append(lab)
    width_in = fig.get_size_inches()[0]
    text = textwrap.fill(title, width=int(width_in * 13))
    n_lines = text.count("\n") + 1
    top = 1.0 - (0.045 * n_lines + (0.06 if labels else 0)) * 4.4 / fig.get_size_inches()[1]
    fig.suptitle(text, fontsize=10, y=0.995)
    if labels:
        fig.legend(
            [handles[lab] for lab in labels],
            labels,
            loc="upper center",
            ncol=len(labels),
            fontsize=9,
            frameon=False,
            bbox_to_anchor=(0.5, top + 0.055 * 4.4 / fig.get_size_inches()[1]),
        )
    fig.tight_layout(rect=(0, 0, 1, top))


def plot_learning(runs: list[Run], path: Path, window: int = 50, title_suffix: str = "") -> Path:
    """Fig. 7: episode return (top) and success rate (bottom) vs env steps, shield on vs off, a column per
    scenario; mean over seeds with a min-max band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [r for r in runs if r.n_episodes > 0]
    scenarios = _scenarios_present(runs) or ["(no runs)"]
    fig, axes = plt.subplots(
        2, len(scenarios), figsize=(max(5.2 * len(scenarios), 8.0), 7.4), squeeze=False, sharex="col"
    )
    grid = _grid_for(runs)
    for j, sc in enumerate(scenarios):
        counts = []
        for shield in ("off", "on"):
            rs = [r for r in runs if r.scenario == sc and r.shield == shield]
            if not rs:
                continue
            counts.append(f"{shield} {len(rs)}")
            for i, key in enumerate(("return", "success")):
                curves = [curve_on_grid(r.episodes["timesteps"], r.episodes[key], grid, window) for r in rs]
                _band(axes[i][j], grid, curves, SHIELD_COLORS[shield], SHIELD_LABELS[shield])
        axes[0][j].set_title(f"{sc} (runs: {', '.join(counts)})" if counts else sc, fontsize=10)
        axes[1][j].set_xlabel("environment steps")
        axes[1][j].set_ylim(-0.02, 1.02)
        axes[1][j].axhline(0.9, color="grey", ls=":", lw=1)
        for i in range(2):
            axes[i][j].grid(alpha=0.3)
    axes[0][0].set_ylabel(f"episode return ({window}-episode mean)")
    axes[1][0].set_ylabel(f"success rate ({window}-episode mean)")
    _finish(
        fig,
        "Fig. 7 (reproduced): PPO learning curves (training episodes) with and without the shield; "
        "line = mean over seeds, band = min-max; dotted: 90 % success" + title_suffix,
        axes,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
