"""Thin rclpy adapters around the core: messages <-> numpy, parameters, diagnostics."""
