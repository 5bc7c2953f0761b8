"""Rendering: HTML reports, figures, terminal summaries, MCAP series."""
