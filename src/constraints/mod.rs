//! constraints (filled in by its issue).
