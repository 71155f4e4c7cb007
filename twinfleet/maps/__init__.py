"""Maps shipped with twinfleet (PGM + YAML, as ROS map_server reads them)."""
