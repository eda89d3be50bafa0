//! Outputs of the `profile` command (to be filled).
