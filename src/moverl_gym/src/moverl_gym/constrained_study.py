"""The shield against constrained RL (issue 27), ROS-free: methods, run folders, tuning choice, aggregation over seeds
with confidence intervals, the figures and the tables. Used by scripts/constrained_study.py; tested on synthetic CSVs.

A run folder is <out>/<method>_<world>_s<seed>/ with config.yaml, episodes.csv (moverl_gym.training.EpisodeLogger),
lagrange.csv (PPO-Lagrangian), model.zip, summary.json (written last: the run is finished) and, once evaluated,
eval_on.csv / eval_off.csv (the final policy with the shield on / off, one row per episode). Tuning runs are the same
under <out>/tuning/, named <method>_<world>_s<seed>_<knob value>.
"""

from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .study import curve_on_grid, read_episodes, smooth

WORLDS = ("table", "human", "case")


@dataclass(frozen=True)
class Method:
    """One trained configuration of the comparison.

    Attributes:
        label: for figures and tables.
        algo: "ppo" (SB3) or "ppolag" (moverl_gym.constrained.PPOLagrangian).
        shield: trained with the shield (ROS graph) or without it (the env's PyBullet backend, in-process).
        knob: the one setting tuned per method: a task key of config/env.yaml, or "lagrange_lr".
        grid: the knob's candidate values (the tuning budget: one run each).
        default: the value used without tuning (--quick).
        cost_limit: PPO-Lagrangian's d (expected steps in contact per episode); None for PPO.
        color: matplotlib colour.
    """

    label: str
    algo: str
    shield: bool
    knob: str
    grid: tuple
    default: float
    cost_limit: float | None = None
    color: str = "k"


METHODS: dict[str, Method] = {
    "ppo_shield": Method(
        "PPO + shield (ours)", "ppo", True, "safety_penalty", (-0.5, -1.0, -2.0), -1.0, color="tab:blue"
    ),
    "ppo_penalty": Method(
        "PPO + contact penalty, no shield", "ppo", False, "contact_penalty", (-1.0, -5.0, -20.0), -5.0, color="tab:red"
    ),
    "ppolag_d0": Method(
        "PPO-Lagrangian d = 0, no shield",
        "ppolag",
        False,
        "lagrange_lr",
        (0.001, 0.005, 0.025),
        0.005,
        0.0,
        "tab:green",
    ),
    "ppolag_d1": Method(
        "PPO-Lagrangian d = 1, no shield",
        "ppolag",
        False,
        "lagrange_lr",
        (0.001, 0.005, 0.025),
        0.005,
        1.0,
        "tab:purple",
    ),
}
RUN_RE = re.compile(
    rf"^(?P<method>{'|'.join(METHODS)})_(?P<world>[a-z]+)_s(?P<seed>-?\d+)(?:_(?P<value>-?[0-9.]+(?:e[+-]?\d+)?))?$"
)
EVAL_FIELDS = ["episode", "seed", "success", "length", "return", "contacts", "contact_steps", "interventions"]


def run_name(method: str, world: str, seed: int, value: float | None = None) -> str:
    """'ppo_shield_table_s0', or with a tuning value 'ppo_shield_table_s100_-0.5'."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r} (known: {sorted(METHODS)})")
    return f"{method}_{world}_s{seed}" + ("" if value is None else f"_{value:g}")


def parse_run_name(name: str) -> dict | None:
    """The inverse of run_name: {method, world, seed, value (None)}; None for a name that is not a run."""
    m = RUN_RE.match(name)
    if not m or m["method"] not in METHODS:
        return None
    return dict(
        method=m["method"],
        world=m["world"],
        seed=int(m["seed"]),
        value=None if m["value"] is None else float(m["value"]),
    )


def select_value(candidates: dict[float, dict], margin: float = 0.05) -> float:
    """The tuning rule, the same for every method: the highest final training success; among the values within
    `margin` of it, the one with the fewest ground-truth contact pairs during training (then the first in the grid).

    Args:
        candidates: knob value -> {"success": final success rate, "contacts": training contact pairs}, in grid order.
        margin: success difference counted as a tie.
    """
    if not candidates:
        raise ValueError("no tuning run finished")
    best = max(c["success"] for c in candidates.values())
    near = [v for v, c in candidates.items() if c["success"] >= best - margin]
    return min(near, key=lambda v: candidates[v]["contacts"])


# -- reading ------------------------------------------------------------------------------------------------------
@dataclass
class Run:
    """A run folder read from disk."""

    path: Path
    method: str
    world: str
    seed: int
    value: float | None
    episodes: dict
    summary: dict | None
    lagrange: dict
    evals: dict  # "on" / "off" -> {column: array}

    @property
    def finished(self) -> bool:
        return self.summary is not None


def load_run(path: Path) -> Run | None:
    path = Path(path)
    meta = parse_run_name(path.name)
    if meta is None:
        return None
    summary = json.loads((path / "summary.json").read_text()) if (path / "summary.json").exists() else None
    evals = {m: read_episodes(path / f"eval_{m}.csv") for m in ("on", "off") if (path / f"eval_{m}.csv").exists()}
    return Run(
        path=path,
        episodes=read_episodes(path / "episodes.csv"),
        summary=summary,
        lagrange=read_episodes(path / "lagrange.csv"),
        evals=evals,
        **meta,
    )


def load_runs(root: Path) -> list[Run]:
    """Every run folder directly under root, in method, world and seed order."""
    root = Path(root)
    if not root.exists():
        return []
    runs = [r for r in (load_run(p) for p in sorted(root.iterdir()) if p.is_dir()) if r is not None]
    order = {m: i for i, m in enumerate(METHODS)}
    worlds = {w: i for i, w in enumerate(WORLDS)}
    return sorted(runs, key=lambda r: (worlds.get(r.world, 99), order[r.method], r.seed, r.value or 0.0))


def _col(data: dict, key: str) -> np.ndarray:
    return np.asarray(data.get(key, np.zeros(0)), dtype=float)


def success_last(run: Run, last: int = 200) -> float:
    s = _col(run.episodes, "success")
    return float(np.mean(s[-last:])) if s.size else math.nan


def total(data: dict, key: str) -> float:
    v = _col(data, key)
    return float(np.nansum(v)) if v.size else 0.0


def eval_stats(run: Run, mode: str) -> dict | None:
    """Success rate, contact pairs (total), steps with contact and shield interventions over the evaluation episodes."""
    e = run.evals.get(mode)
    if not e or _col(e, "success").size == 0:
        return None
    return dict(
        episodes=int(_col(e, "success").size),
        success=float(np.mean(_col(e, "success"))),
        contacts=total(e, "contacts"),
        contact_steps=total(e, "contact_steps"),
        interventions=total(e, "interventions"),
        length=float(np.mean(_col(e, "length"))),
    )


# -- statistics ---------------------------------------------------------------------------------------------------
def mean_ci(values, confidence: float = 0.95) -> tuple[float, float, int]:
    """Mean, half-width of Student's t confidence interval over the finite values, and their number (NaN half-width
    for fewer than 2)."""
    from scipy import stats

    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    if v.size == 0:
        return math.nan, math.nan, 0
    if v.size == 1:
        return float(v[0]), math.nan, 1
    half = stats.t.ppf(0.5 + confidence / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size)
    return float(v.mean()), float(half), int(v.size)


def cumulative_on_grid(timesteps, values, grid) -> np.ndarray:
    """Cumulative sum of a per-episode quantity against env steps (a step function: the total of the episodes ended by
    then), on grid; NaN beyond the run's last episode."""
    t = np.asarray(timesteps, dtype=float)
    c = np.cumsum(np.nan_to_num(np.asarray(values, dtype=float)))
    grid = np.asarray(grid, dtype=float)
    out = np.full(grid.shape, np.nan)
    if t.size == 0:
        return out
    idx = np.searchsorted(t, grid, side="right")
    inside = grid <= t[-1]
    out[inside] = np.where(idx[inside] > 0, c[np.maximum(idx[inside] - 1, 0)], 0.0)
    return out


def _ci_band(curves, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per grid point: mean, lower and upper t-interval bounds over the seeds (curves: seeds x grid)."""
    a = np.atleast_2d(np.asarray(curves, dtype=float))
    mean, lo, hi = (np.full(a.shape[1], np.nan) for _ in range(3))
    for j in range(a.shape[1]):
        m, h, n = mean_ci(a[:, j], confidence)
        if n:
            mean[j] = m
            lo[j], hi[j] = (m - h, m + h) if n > 1 else (m, m)
    return mean, lo, hi


# -- tables -------------------------------------------------------------------------------------------------------
def summarize(runs: list[Run], last: int = 200) -> list[dict]:
    """One row per (world, method) over finished runs: final training success, contacts during training, evaluation
    in the method's own deployment (the shield as trained) and wall-clock; mean and 95 % CI half-width over seeds."""
    rows = []
    groups: dict[tuple, list[Run]] = {}
    for r in runs:
        if r.finished and r.value is None:
            groups.setdefault((r.world, r.method), []).append(r)
    order = {m: i for i, m in enumerate(METHODS)}
    worlds = {w: i for i, w in enumerate(WORLDS)}
    for (world, method), rs in sorted(groups.items(), key=lambda kv: (worlds.get(kv[0][0], 99), order[kv[0][1]])):
        own = "on" if METHODS[method].shield else "off"
        row = {
            "world": world,
            "method": method,
            "label": METHODS[method].label,
            "seeds": " ".join(str(r.seed) for r in rs),
        }
        stats = {
            "success": [success_last(r, last) for r in rs],
            "train_contacts": [total(r.episodes, "contacts") for r in rs],
            "train_contact_steps": [total(r.episodes, "cost_contact") for r in rs],
            "train_interventions": [total(r.episodes, "interventions") for r in rs],
            "eval_success": [(eval_stats(r, own) or {}).get("success", math.nan) for r in rs],
            "eval_contacts": [(eval_stats(r, own) or {}).get("contacts", math.nan) for r in rs],
            "wall_time": [float(r.summary.get("wall_time", math.nan)) for r in rs],
            "steps_per_second": [float(r.summary.get("steps_per_second", math.nan)) for r in rs],
            "multiplier": [float(r.summary.get("multiplier", math.nan)) for r in rs],
            "episode_cost_last": [float(r.summary.get("episode_cost_last", math.nan)) for r in rs],
        }
        for key, values in stats.items():
            m, h, n = mean_ci(values)
            row[f"{key}_mean"], row[f"{key}_ci95"] = m, h
            if key in ("success", "train_contacts", "eval_contacts"):
                row[f"{key}_per_seed"] = " ".join("nan" if not np.isfinite(x) else f"{x:g}" for x in values)
        row["n_runs"] = len(rs)
        row["n_evaluated"] = sum(eval_stats(r, own) is not None for r in rs)
        row["timesteps"] = int(max((_col(r.episodes, "timesteps")[-1:] for r in rs), key=len, default=[0])[0])
        row["eval_mode"] = own
        rows.append(row)
    return rows


def summarize_2x2(runs: list[Run]) -> list[dict]:
    """One row per (world, method, deployment: shield on / off) over the evaluated runs: the final policy's success,
    contact pairs and shield interventions per episode (mean and 95 % CI over seeds)."""
    rows = []
    order = {m: i for i, m in enumerate(METHODS)}
    worlds = {w: i for i, w in enumerate(WORLDS)}
    keys = sorted(
        {(r.world, r.method) for r in runs if r.finished and r.value is None},
        key=lambda k: (worlds.get(k[0], 99), order[k[1]]),
    )
    for world, method in keys:
        rs = [r for r in runs if r.world == world and r.method == method and r.finished and r.value is None]
        for mode in ("on", "off"):
            st = [eval_stats(r, mode) for r in rs]
            st = [s for s in st if s is not None]
            if not st:
                continue
            row = {
                "world": world,
                "method": method,
                "label": METHODS[method].label,
                "trained_with_shield": METHODS[method].shield,
                "deployed_with_shield": mode == "on",
                "n_runs": len(st),
                "episodes_per_run": st[0]["episodes"],
            }
            for key in ("success", "contacts", "contact_steps", "interventions", "length"):
                per_ep = [s[key] / (1 if key in ("success", "length") else s["episodes"]) for s in st]
                m, h, _ = mean_ci(per_ep)
                name = key if key in ("success", "length") else f"{key}_per_episode"
                row[f"{name}_mean"], row[f"{name}_ci95"] = m, h
            row["runs_with_contacts"] = sum(s["contacts"] > 0 for s in st)
            rows.append(row)
    return rows


def write_csv(rows: list[dict], path: Path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        if rows:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            for r in rows:
                w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def _pm(m: float, h: float, fmt: str = "{:.0f}", scale: float = 1.0) -> str:
    if not np.isfinite(m):
        return "n/a"
    s = fmt.format(scale * m)
    return s if not np.isfinite(h) else f"{s} ± {fmt.format(scale * h)}"


def _pct(m: float, h: float) -> str:
    """A rate as a percentage with its CI half-width, or n/a."""
    return "n/a" if not np.isfinite(m) else f"{_pm(m, h, '{:.1f}', 100)} %"


def markdown_table(rows: list[dict], last: int = 200) -> str:
    """The comparison table (GitHub markdown): mean ± 95 % CI half-width over seeds."""
    head = (
        f"| world | method | runs | final success (last {last} training episodes) | contact pairs during training "
        "| steps with contact during training | shield interventions during training | evaluation (own deployment): "
        "success | evaluation: contact pairs | wall-clock per run (s) | env steps/s | final multiplier |"
    )
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for r in rows:
        lines.append(
            f"| {r['world']} | {r['label']} | {r['n_runs']} "
            f"| {_pct(r['success_mean'], r['success_ci95'])} "
            f"| {_pm(r['train_contacts_mean'], r['train_contacts_ci95'], '{:,.0f}')} "
            f"| {_pm(r['train_contact_steps_mean'], r['train_contact_steps_ci95'], '{:,.0f}')} "
            f"| {_pm(r['train_interventions_mean'], r['train_interventions_ci95'], '{:,.0f}')} "
            f"| {_pct(r['eval_success_mean'], r['eval_success_ci95'])} (shield {r['eval_mode']}) "
            f"| {_pm(r['eval_contacts_mean'], r['eval_contacts_ci95'], '{:,.1f}')} "
            f"| {_pm(r['wall_time_mean'], r['wall_time_ci95'])} | {_pm(r['steps_per_second_mean'], math.nan)} "
            f"| {_pm(r['multiplier_mean'], r['multiplier_ci95'], '{:.2f}')} |"
        )
    return "\n".join(lines) + "\n"


def markdown_2x2(rows: list[dict]) -> str:
    """The deployment table: every final policy with the shield on and off."""
    head = (
        "| world | method (trained) | deployed with shield | runs x episodes | success | contact pairs / episode "
        "| steps with contact / episode | shield interventions / episode | runs with any contact |"
    )
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for r in rows:
        lines.append(
            f"| {r['world']} | {r['label']} | {'on' if r['deployed_with_shield'] else 'off'} "
            f"| {r['n_runs']} x {r['episodes_per_run']} | {_pct(r['success_mean'], r['success_ci95'])} "
            f"| {_pm(r['contacts_per_episode_mean'], r['contacts_per_episode_ci95'], '{:.2f}')} "
            f"| {_pm(r['contact_steps_per_episode_mean'], r['contact_steps_per_episode_ci95'], '{:.2f}')} "
            f"| {_pm(r['interventions_per_episode_mean'], r['interventions_per_episode_ci95'], '{:.2f}')} "
            f"| {r['runs_with_contacts']} of {r['n_runs']} |"
        )
    return "\n".join(lines) + "\n"


def per_run_rows(runs: list[Run], last: int = 200) -> list[dict]:
    """One row per run (finished or not): steps, episodes, final success, training contacts, evaluations, wall-clock."""
    rows = []
    for r in runs:
        sm = r.summary or {}
        t = _col(r.episodes, "timesteps")
        row = dict(
            run=r.path.name,
            world=r.world,
            method=r.method,
            seed=r.seed,
            finished=r.finished,
            timesteps=int(t[-1]) if t.size else 0,
            episodes=int(t.size),
            success_last=success_last(r, last),
            train_contacts=total(r.episodes, "contacts"),
            train_contact_steps=total(r.episodes, "cost_contact"),
            train_interventions=total(r.episodes, "interventions"),
            wall_time=float(sm.get("wall_time", math.nan)),
            steps_per_second=float(sm.get("steps_per_second", math.nan)),
            multiplier=float(sm.get("multiplier", math.nan)),
        )
        for mode in ("on", "off"):
            e = eval_stats(r, mode) or {}
            row[f"eval_{mode}_success"] = e.get("success", math.nan)
            row[f"eval_{mode}_contacts"] = e.get("contacts", math.nan)
            row[f"eval_{mode}_interventions"] = e.get("interventions", math.nan)
        rows.append(row)
    return rows


def markdown_runs(rows: list[dict]) -> str:
    """per_run_rows as a markdown table."""
    head = (
        "| run | finished | env steps | episodes | final success | contact pairs (training) | steps with contact "
        "| interventions | eval shield on: success / contacts | eval shield off: success / contacts | wall-clock (s) |"
    )
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]

    def pct(x):
        return "-" if not np.isfinite(x) else f"{100 * x:.0f} %"

    def num(x):
        return "-" if not np.isfinite(x) else f"{x:,.0f}"

    for r in rows:
        lines.append(
            f"| {r['run']} | {'yes' if r['finished'] else 'no'} | {r['timesteps']:,} | {r['episodes']:,} "
            f"| {pct(r['success_last'])} | {num(r['train_contacts'])} | {num(r['train_contact_steps'])} "
            f"| {num(r['train_interventions'])} | {pct(r['eval_on_success'])} / {num(r['eval_on_contacts'])} "
            f"| {pct(r['eval_off_success'])} / {num(r['eval_off_contacts'])} | {num(r['wall_time'])} |"
        )
    return "\n".join(lines) + "\n"


def markdown_tuning(path: Path) -> str:
    """The tuning runs (tuning.csv) as a markdown table."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    head = "| method | knob | value | final success | contact pairs | steps with contact | interventions | chosen |"
    lines = [head, "|" + "|".join(["---"] * 8) + "|"]
    for r in rows:
        label = METHODS[r["method"]].label if r["method"] in METHODS else r["method"]
        lines.append(
            f"| {label} | {r['knob']} | {float(r['value']):g} | {100 * float(r['success']):.1f} % "
            f"| {float(r['contacts']):,.0f} | {float(r['contact_steps']):,.0f} | {float(r['interventions']):,.0f} "
            f"| {'**yes**' if r['selected'] == 'True' else ''} |"
        )
    return "\n".join(lines) + "\n"


def curves_csv(runs: list[Run], path: Path, points: int = 101, window: int = 50) -> None:
    """The figures' data: per run and grid step, cumulative contact pairs and steps with contact, and the success rate
    over the last `window` episodes."""
    rows = []
    for r in runs:
        if not r.finished or r.value is not None:
            continue
        t = _col(r.episodes, "timesteps")
        grid = np.linspace(0, float(t[-1]) if t.size else 0.0, points)
        cum = cumulative_on_grid(t, _col(r.episodes, "contacts"), grid)
        cum_steps = cumulative_on_grid(t, _col(r.episodes, "cost_contact"), grid)
        succ = curve_on_grid(t, _col(r.episodes, "success"), grid, window)
        for g, a, b, s in zip(grid, cum, cum_steps, succ):
            rows.append(
                dict(
                    world=r.world,
                    method=r.method,
                    seed=r.seed,
                    timesteps=int(g),
                    cumulative_contacts=a,
                    cumulative_contact_steps=b,
                    success=s,
                )
            )
    write_csv(rows, path)


# -- figures ------------------------------------------------------------------------------------------------------
def plot_world(runs: list[Run], world: str, path: Path, window: int = 50, title_suffix: str = "") -> Path:
    """One figure per world: cumulative ground-truth contact pairs (symlog) and the success rate of the training
    episodes against env steps, one line per method (mean over seeds) with its 95 % confidence band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rs_all = [r for r in runs if r.world == world and r.finished and r.value is None]
    tmax = max(
        (float(_col(r.episodes, "timesteps")[-1]) for r in rs_all if _col(r.episodes, "timesteps").size), default=1
    )
    grid = np.linspace(0.0, tmax, 300)
    fig, (ax_c, ax_s) = plt.subplots(1, 2, figsize=(12.5, 4.6))
    for method, spec in METHODS.items():
        rs = [r for r in rs_all if r.method == method]
        if not rs:
            continue
        label = f"{spec.label} ({len(rs)} seeds)"
        cum = [cumulative_on_grid(_col(r.episodes, "timesteps"), _col(r.episodes, "contacts"), grid) for r in rs]
        succ = [curve_on_grid(_col(r.episodes, "timesteps"), _col(r.episodes, "success"), grid, window) for r in rs]
        for ax, curves in ((ax_c, cum), (ax_s, succ)):
            mean, lo, hi = _ci_band(curves)
            ok = np.isfinite(mean)
            ax.plot(grid[ok], mean[ok], color=spec.color, lw=1.8, label=label)
            if len(rs) > 1:
                ax.fill_between(grid[ok], lo[ok], hi[ok], color=spec.color, alpha=0.18, lw=0)
    ax_c.set_yscale("symlog", linthresh=10)
    ax_c.set_ylim(bottom=0)
    ax_c.set_ylabel("cumulative ground-truth contact pairs")
    ax_s.set_ylabel(f"success rate ({window}-episode mean)")
    ax_s.set_ylim(-0.02, 1.02)
    for ax in (ax_c, ax_s):
        ax.set_xlabel("environment steps")
        ax.grid(alpha=0.3)
    ax_s.legend(loc="lower right", fontsize=8)
    fig.suptitle(
        f"{world}: the shield against a contact penalty and PPO-Lagrangian (training episodes; mean over seeds, "
        f"band = 95 % CI){title_suffix}",
        fontsize=10,
    )
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def lagrange_curves(runs: list[Run], path: Path, window: int = 10) -> Path:
    """PPO-Lagrangian's multiplier and episode cost (steps with contact per episode, smoothed over `window` updates)
    against env steps, one panel per world: what the constrained agent did."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    worlds = [w for w in WORLDS if any(r.world == w for r in runs)]
    fig, axes = plt.subplots(2, max(len(worlds), 1), figsize=(4.6 * max(len(worlds), 1), 6.4), squeeze=False)
    for j, world in enumerate(worlds):
        for method, spec in METHODS.items():
            if spec.algo != "ppolag":
                continue
            for k, r in enumerate(x for x in runs if x.world == world and x.method == method and x.value is None):
                t = _col(r.lagrange, "timesteps")
                if not t.size:
                    continue
                cost = _col(r.lagrange, "episode_cost")
                ok = np.isfinite(cost)
                label = spec.label if k == 0 else None
                axes[0][j].plot(t, _col(r.lagrange, "multiplier"), color=spec.color, lw=0.8, alpha=0.7, label=label)
                axes[1][j].plot(t[ok], smooth(cost[ok], window), color=spec.color, lw=0.8, alpha=0.7)
            if spec.cost_limit is not None:
                axes[1][j].axhline(spec.cost_limit, color=spec.color, ls=":", lw=1)
        axes[0][j].set_title(world, fontsize=10)
        axes[1][j].set_xlabel("environment steps")
        axes[1][j].set_yscale("symlog", linthresh=1)
        axes[1][j].set_ylim(bottom=0)  # a cost is never negative
        for i in range(2):
            axes[i][j].grid(alpha=0.3)
    axes[0][0].set_ylabel("Lagrange multiplier")
    axes[1][0].set_ylabel(f"steps with contact per episode\n({window}-update mean; dotted: the limit d)")
    if axes[0][0].get_legend_handles_labels()[0]:
        axes[0][0].legend(fontsize=8)
    fig.suptitle("PPO-Lagrangian: multiplier and episode cost, every seed", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
