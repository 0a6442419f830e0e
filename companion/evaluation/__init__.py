"""Tracker evaluation: metrics, sequence loading, running trackers, reports (`companion eval`)."""
