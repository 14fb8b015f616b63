"""Shared test settings: every test runs offline and seeded."""
