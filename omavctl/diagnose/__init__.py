"""Judging a model against flights: metrics, effect scoring, verdict, evaluation file."""
