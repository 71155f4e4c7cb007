"""The parameter methods of `rclpy.node.Node`: declared with defaults, overridden by the
launch (`params:` of the scenario, as ``--ros-args -p``), set at run time through the
on-set callbacks. Values live in the engine's state, so the checker sees a change."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from twinfleet.rclpy.api.exceptions import (
    InvalidParameterTypeException,
    ParameterAlreadyDeclaredException,
    ParameterNotDeclaredException,
)
from twinfleet.rclpy.api.parameter import Parameter, type_of


def set_result(successful: bool, reason: str = "") -> Any:
    """An rcl_interfaces/msg/SetParametersResult."""
    from twinfleet.rclpy.wire import load_interface
    return load_interface("rcl_interfaces", "msg").SetParametersResult(
        successful=successful, reason=reason)


class ParametersMixin:
    """Parameter methods; `self._tf_engine` holds the values (`Dynamic.params`)."""

    _tf_engine: Any

    def declare_parameter(self, name: str, value: Any = None, descriptor: Any = None,
                          ignore_override: bool = False) -> Parameter:
        """Declare `name` with a default; a launch override wins unless `ignore_override`."""
        engine = self._tf_engine
        if name in engine.dyn.params:
            raise ParameterAlreadyDeclaredException(name)
        if isinstance(value, Parameter.Type):
            value = None
        overrides = engine.overrides
        if name in overrides and not ignore_override:
            given = overrides[name]
            if value is not None and type(value) is float and type(given) is int:
                given = float(given)
            if value is not None and type_of(given) is not type_of(value):
                raise InvalidParameterTypeException(
                    f"parameter {name!r}: the override {given!r} is not of the declared "
                    f"type {type_of(value).name}")
            value = given
        engine.declared[name] = (descriptor, type_of(value))
        engine.dyn.params[name] = value
        return Parameter(name, value=value)

    def declare_parameters(self, namespace: str, parameters: Sequence[Any],
                           ignore_override: bool = False) -> list[Parameter]:
        """Declare several: ``(name, value)`` or ``(name, value, descriptor)`` tuples."""
        out = []
        for item in parameters:
            name, value = (item[0], item[1] if len(item) > 1 else None)
            full = f"{namespace}.{name}" if namespace else name
            out.append(self.declare_parameter(full, value, None, ignore_override))
        return out

    def undeclare_parameter(self, name: str) -> None:
        """Forget a declared parameter."""
        self._value(name)
        del self._tf_engine.dyn.params[name]

    def has_parameter(self, name: str) -> bool:
        """True for a declared parameter."""
        return name in self._tf_engine.dyn.params

    def _value(self, name: str) -> Any:
        try:
            return self._tf_engine.dyn.params[name]
        except KeyError:
            raise ParameterNotDeclaredException(name) from None

    def get_parameter(self, name: str) -> Parameter:
        """The parameter `name` (raises if not declared)."""
        return Parameter(name, value=self._value(name))

    def get_parameter_or(self, name: str, alternative_value: Parameter | None = None) -> Any:
        """The parameter, or `alternative_value` when not declared."""
        if not self.has_parameter(name):
            return alternative_value if alternative_value is not None else Parameter(name)
        return self.get_parameter(name)

    def get_parameters(self, names: Sequence[str]) -> list[Parameter]:
        """Several parameters."""
        return [self.get_parameter(n) for n in names]

    def get_parameters_by_prefix(self, prefix: str) -> dict[str, Parameter]:
        """The parameters under ``prefix.``, keyed by the rest of their name."""
        head = f"{prefix}." if prefix else ""
        return {k[len(head):]: Parameter(k, value=v)
                for k, v in self._tf_engine.dyn.params.items() if k.startswith(head)}

    def add_on_set_parameters_callback(self, callback: Callable[[list[Parameter]], Any]) -> None:
        """`callback(parameters) -> SetParametersResult` may refuse a change."""
        self._tf_engine.dyn.on_set.insert(0, callback)

    def remove_on_set_parameters_callback(self, callback: Callable[..., Any]) -> None:
        """Forget an on-set callback."""
        self._tf_engine.dyn.on_set.remove(callback)

    def set_parameters(self, parameter_list: Sequence[Parameter]) -> list[Any]:
        """Set parameters one by one; each result says whether it was applied."""
        return [self._set_all([p]) for p in parameter_list]

    def set_parameters_atomically(self, parameter_list: Sequence[Parameter]) -> Any:
        """Set all or none."""
        return self._set_all(list(parameter_list))

    def _set_all(self, parameters: list[Parameter]) -> Any:
        engine = self._tf_engine
        for p in parameters:
            if p.name not in engine.dyn.params:
                return set_result(False, f"parameter {p.name!r} is not declared")
            declared = engine.declared.get(p.name, (None, Parameter.Type.NOT_SET))[1]
            if declared is not Parameter.Type.NOT_SET and p.type_ is not declared:
                return set_result(False, f"parameter {p.name!r} has type {declared.name}, "
                                         f"not {p.type_.name}")
        for callback in list(engine.dyn.on_set):
            result = callback(parameters)
            if not getattr(result, "successful", False):
                return result
        for p in parameters:
            engine.dyn.params[p.name] = p.value
        return set_result(True)
