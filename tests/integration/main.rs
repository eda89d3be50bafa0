//! One integration-test binary (keeps link time low); each file is a module.
mod render;
