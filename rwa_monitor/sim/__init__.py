"""Seeded telemetry generators that write the telemetry schema with truth columns."""
