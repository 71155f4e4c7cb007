"""The node contract and the live driver, in wings that show the layers.

    contract/  what a node is and says: Node, Context, messages, names, kinds, snapshots, traces
    scenario/  one description of a fleet for both drivers: files, settings, parameters, properties
    core/      one node's event handling with no I/O (sans-IO), and what observes it
    host/      the asyncio loop, the clock and the Zenoh transport under one node
    access/    reaching a running fleet: credentials, the registry of fleets, connections
    fleet/     the launcher, node processes and the live verdict
    tools/     monitors (ROS 2-style verbs), recordings, the web viewer and the Foxglove bridge
    cli/       the runtime's commands

Each wing imports only the wings below it (tests/test_layering.py: `RULES`): contract
nothing of ours; scenario and core the contract; host core and scenario; access host; fleet
access; tools fleet; cli anything. The contract, scenario and core load neither asyncio nor Zenoh, so the
checker can use them. `tools/` groups three wings (monitor, record, view: `TOOLS_RULES`).
"""

__all__ = [
    "access",
    "cli",
    "contract",
    "core",
    "fleet",
    "host",
    "scenario",
    "tools",
]
