//! An independent reference ray tracer for spherically stratified air (filled in separately).
