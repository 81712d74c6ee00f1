//! bbw (filled in by its issue).
