"""Geodesy, Earth model and standard atmosphere."""
