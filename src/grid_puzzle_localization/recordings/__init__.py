"""A user's own recordings (a folder of scans with poses and times) turned into experiment inputs."""
