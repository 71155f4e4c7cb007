"""The node contract and the live driver.

The contract modules (`node`, `context`, `dispatch`, `messages`, `names`,
`snapshot`) import neither Zenoh nor asyncio: the checker imports them. The
public node API is re-exported by the top-level `twinfleet` package. Live
modules (`zenoh_transport`, `host`, `launcher`, ...) are imported explicitly
where needed.
"""
