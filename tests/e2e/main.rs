//! End-to-end tests: the `ballbar` command and its plugins, driven as a user drives them.

mod aliases;
mod archive;
mod chain_files;
mod common;
mod compensate;
mod compensate_controllers;
mod compensate_cross;
mod compensate_existing;
mod compensate_independent;
mod diagnose;
mod documents;
mod fit;
mod five_axis;
mod history;
mod install;
mod outputs;
mod plugins;
mod readers;
mod report;
mod switch;
mod time_origin;
mod vendor;
