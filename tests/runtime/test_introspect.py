"""What a node says about itself in ``@info``: its services' request and reply types."""

from __future__ import annotations

from twinfleet import Context, Node, service
from twinfleet.nodes.demo import Adder
from twinfleet.runtime.host.introspect import node_description


class Untyped(Node):
    @service("/echo")
    def echo(self, ctx: Context, req):  # no annotations: the types are not known
        return req


def test_service_types_come_from_the_handler_annotations():
    info = node_description(Adder("adder"), "twinfleet.nodes.demo:Adder")
    assert info["service_types"] == {
        "/add_two_ints": ["example_interfaces/AddTwoInts_Request",
                          "example_interfaces/AddTwoInts_Response"]}


def test_a_service_without_annotations_says_it_does_not_know():
    assert node_description(Untyped("u"), "m:Untyped")["service_types"] == {"/echo": ["?", "?"]}
