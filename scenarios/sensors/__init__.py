"""Simulated sensors (LiDAR, GPS, AHRS) and the perception they feed the loop."""
