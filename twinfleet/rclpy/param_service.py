"""`twinfleet param set NODE NAME VALUE` on a live rclpy node: every adapter serves
``~/set_parameter``, which sets one parameter through the node's on-set callbacks as
rclpy's ``~/set_parameters`` service does (the value travels as YAML text)."""

from __future__ import annotations

from typing import Any

import yaml

from twinfleet.runtime.contract.messages import message

#: The service every rclpy node serves, relative to the node (``/<ns>/<node>/set_parameter``).
SERVICE = "~/set_parameter"


@message("twinfleet/SetParameter")
class SetParameter:
    """Set parameter `name` to the YAML value `value`."""

    name: str = ""
    value: str = ""


@message("twinfleet/SetParameterResult")
class SetParameterResult:
    """Whether the parameter was set, and why not."""

    successful: bool = False
    reason: str = ""


def set_parameter(node: Any, request: SetParameter) -> SetParameterResult:
    """Set one parameter of the rclpy `node` (its on-set callbacks may refuse)."""
    from twinfleet.rclpy.api.parameter import Parameter

    try:
        value = yaml.safe_load(request.value)
        parameter = Parameter(request.name, value=value)
    except (yaml.YAMLError, TypeError) as exc:
        return SetParameterResult(False, f"bad value {request.value!r}: {exc}")
    result = node.set_parameters([parameter])[0]
    return SetParameterResult(bool(result.successful), str(getattr(result, "reason", "")))
