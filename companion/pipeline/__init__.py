"""Pieces of the asyncio pipeline owned by :mod:`companion.app`."""
