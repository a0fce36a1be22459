"""MoveRL Gymnasium environments. Importing this package registers every env id (see ENV_IDS)."""

from .registration import ENV_IDS, FLAT_ENV_IDS, GOAL_ENV_IDS, register_envs

register_envs()

__all__ = ["ENV_IDS", "FLAT_ENV_IDS", "GOAL_ENV_IDS", "register_envs"]
