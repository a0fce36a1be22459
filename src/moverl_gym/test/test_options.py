"""The front-ends' options are one set (moverl_gym.options): train.py and rllib_train.py take the same names, units and
choices; evaluate.py and study.py those that apply; what RLlib cannot honour is refused, never ignored. No ROS."""

import argparse
from pathlib import Path

import pytest
import yaml

import moverl_gym
from moverl_gym import options
from moverl_gym.launch_args import CHOICES
from moverl_gym.paths import load_script

pytestmark = pytest.mark.core

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"
HYPERPARAMS = Path(__file__).resolve().parents[1] / "config" / "hyperparams"


def _load(name):
    return load_script(SCRIPTS / f"{name}.py")


train = _load("train")
rllib_train = _load("rllib_train")
evaluate = _load("evaluate")
study = _load("study")


def actions(parser: argparse.ArgumentParser) -> dict:
    """dest -> the action, for every option of a parser."""
    return {a.dest: a for a in parser._actions if a.option_strings}


def shape(action) -> tuple:
    """What must agree between front-ends: the flags' names, choices, type, default, nargs and kind of action."""
    return (tuple(action.option_strings), action.choices, action.type, action.default, action.nargs, type(action))


@pytest.mark.parametrize("name", options.TRAINING)
def test_training_front_ends_share_every_option(name):
    sb3, rllib = actions(train.build_parser()), actions(rllib_train.build_parser())
    a, b = shape(sb3[name]), shape(rllib[name])
    if name == "n_envs":  # rllib_train.py also takes RLlib's name for it
        assert b[0] == (*a[0], "--num-env-runners")
        a, b = a[1:], b[1:]
    assert a == b


def test_shared_choices_come_from_their_one_list():
    sb3 = actions(train.build_parser())
    assert tuple(sb3["obstacles"].choices) == CHOICES["obstacles"]  # launch_args: moverl.launch's values
    assert list(sb3["env"].choices) == moverl_gym.ENV_IDS
    ev, st = actions(evaluate.build_parser()), actions(study.build_parser())
    for name in ("seed", "shield", "obstacles", "task", "graph", "video"):
        assert shape(ev[name])[:3] == shape(sb3[name])[:3], name  # flags, choices, type (defaults: as trained)
    assert shape(st["algo"]) == shape(sb3["algo"]) and st["shields"].choices == options.SHIELD
    assert st["task"].type is options.task_item


def test_units_steps_over_every_env():
    args = train.parse_args(["--checkpoint-freq", "4000", "-n", "8000", "--n-envs", "2"])
    assert (args.checkpoint_freq, args.n_timesteps, args.n_envs) == (4000, 8000, 2)
    args = rllib_train.parse_args(["--checkpoint-freq", "4000", "--num-env-runners", "3"])
    assert (args.checkpoint_freq, args.n_envs) == (4000, 3)
    for bad in (["--checkpoint-freq", "-1"], ["--n-envs", "0"], ["-n", "0"], ["--video", "-2"]):
        for front_end in (train, rllib_train):
            with pytest.raises(SystemExit) as e:
                front_end.parse_args(bad)
            assert e.value.code == 2


def test_task_items_are_checked_when_parsed(capsys):
    assert train.parse_args(["--task", "start_noise=0", "--task", "kappa=5"]).task == ["start_noise=0", "kappa=5"]
    assert options.task_dict(["start_noise=0", "kappa=5", "goal_tolerance=0.02"]) == {
        "start_noise": 0,
        "kappa": 5,
        "goal_tolerance": 0.02,
    }
    for bad, says in (("start_nois=0", "did you mean start_noise?"), ("start_noise", "takes KEY=VALUE")):
        for front_end in (train, rllib_train, evaluate, study):
            argv = ["run"] if front_end is evaluate else []
            with pytest.raises(SystemExit):
                front_end.parse_args([*argv, "--task", bad])
            assert says in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv,says",
    [
        (["--algo", "sac"], "trains PPO only"),
        (["--env", "MoveRL/PandaReachTableGoal-v0"], "goal-conditioned ids"),
        (["--graph", "attach"], "launches its own graph"),
        (["--device", "cuda"], "learner runs on the CPU"),
        (["--address", "127.0.0.1:6379", "--local-nodes", "2"], "--local-nodes"),
    ],
)
def test_rllib_refuses_what_it_cannot_honour(argv, says, capsys):
    with pytest.raises(SystemExit) as e:
        rllib_train.parse_args(argv)
    assert e.value.code == 2 and says in capsys.readouterr().err
    train.parse_args([a for a in argv if a not in ("--address", "127.0.0.1:6379", "--local-nodes", "2")])  # SB3: fine


def test_rllib_passes_obstacles_task_and_recover_to_every_runner_env():
    args = rllib_train.parse_args(["--obstacles", "sensed", "--task", "start_noise=0", "--recover", "off"])
    assert rllib_train.env_kwargs(args) == dict(
        shield=True, graph="launch", recover=False, launch_args={"obstacles": "sensed"}, task={"start_noise": 0}
    )
    assert rllib_train.env_kwargs(rllib_train.parse_args(["--shield", "off"])) == dict(
        shield=False, graph="launch", recover="auto"
    )


def test_hyper_parameter_files_name_parallel_envs_alike():
    for name in ("ppo", "sac", "td3", "rllib_ppo"):
        table = yaml.safe_load((HYPERPARAMS / f"{name}.yml").read_text())
        for entry in table.values():
            assert "num_env_runners" not in entry, name
    assert yaml.safe_load((HYPERPARAMS / "rllib_ppo.yml").read_text())["default"]["n_envs"] >= 1
    assert "n_envs" in rllib_train.RUN_KEYS


def test_changing_a_shared_choice_or_type_is_refused():
    p = argparse.ArgumentParser()
    with pytest.raises(ValueError, match="shared"):
        options.add(p, "shield", shield=dict(choices=("yes", "no")))
    with pytest.raises(ValueError, match="not added"):
        options.add(argparse.ArgumentParser(), "seed", shield=dict(default=None))
