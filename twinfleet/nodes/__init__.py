"""Robot and map-server nodes of twinfleet, and their pure domain code."""
