"""Ray, imported on demand, and the Tune API across Ray versions (Python 3.8's Ray 2.10 keeps some
of Tune's names in ``ray.train``). Used by the sweeps (:mod:`fr5_rl.training.tune`) and by the
evaluation spread over a cluster (:mod:`fr5_rl.training.ray_eval`); importing it needs no Ray."""
from __future__ import annotations

from types import SimpleNamespace

from ..config import ConfigError


def import_ray():
    """``ray`` and ``ray.tune``, or a :class:`ConfigError` that says how to install them."""
    try:
        import ray
        from ray import tune
    except ImportError as error:
        raise ConfigError(f"Ray Tune is not installed ({error}); run `make setup` (it installs the pinned "
                          "ray[tune] from requirements.txt) and source env.sh") from None
    return ray, tune


# Names that moved from ray.train to ray.tune in Ray 2.x (Python 3.8's Ray 2.10 has them in ray.train).
_TUNE_API = ("report", "get_checkpoint", "get_context", "Checkpoint", "RunConfig", "FailureConfig",
             "CheckpointConfig")


def tune_api() -> SimpleNamespace:
    """The Tune functions and config classes, from ``ray.tune`` or (older Ray) ``ray.train``."""
    _, tune = import_ray()
    try:
        from ray import train as legacy
    except ImportError:  # pragma: no cover - a Ray without ray.train
        legacy = None
    return SimpleNamespace(**{name: getattr(tune, name, None) or getattr(legacy, name) for name in _TUNE_API})
