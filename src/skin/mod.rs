//! skin (filled in by its issue).
