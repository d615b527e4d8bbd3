"""MCAP recording, replay and configuration files."""
