"""Goal-conditioned environments and their registry: `make("maze-point", **env_config)`."""

from .registry import ENV_FACTORIES, UnknownEnvError, env_ids, make, register_with_ray

__all__ = ["ENV_FACTORIES", "UnknownEnvError", "env_ids", "make", "register_with_ray"]
