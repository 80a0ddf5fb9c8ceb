"""Readers of recorded robot logs (public benchmark data) into usvdrake's sensor messages."""
