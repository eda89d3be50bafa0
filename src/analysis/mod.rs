//! Stage 5 — analysis (placeholder)
