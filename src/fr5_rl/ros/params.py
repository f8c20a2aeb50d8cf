"""~private parameters with their defaults from config/<node>.yaml (one place for defaults)."""
from __future__ import annotations

from typing import Any, Dict

import rospy

from ..config import load_yaml


def node_parameters(config_name: str) -> Dict[str, Any]:
    """Every key of ``config/<config_name>.yaml``, overridden by the node's ~private params."""
    defaults = load_yaml(config_name)
    return {key: rospy.get_param(f"~{key}", value) for key, value in defaults.items()}
