"""Evaluation of estimates against truth or withheld GNSS."""
