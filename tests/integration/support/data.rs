//! Paths of the repository's own test inputs.
