//! End-to-end tests: the `ballbar` command and its plugins, driven as a user drives them.

mod common;
mod fit;
mod plugins;
