"""Readers and writers for the formats skinning data comes in (filled in by issue 2)."""
