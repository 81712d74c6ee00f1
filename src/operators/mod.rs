//! operators (filled in by its issue).
