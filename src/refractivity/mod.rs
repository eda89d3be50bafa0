//! Stage 3 — refractivity (to be built).
