"""Sensor error models shared by the simulator and every estimator."""
