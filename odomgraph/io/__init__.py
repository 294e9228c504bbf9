"""Files: log directories, robot.toml, estimate directories."""
