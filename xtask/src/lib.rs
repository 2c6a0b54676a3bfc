//! The part of the project's chores that other packages use: the installed layout and the
//! `dist`, `install` and `uninstall` tasks ([`layout`]), standard library only, which the
//! end-to-end tests run on the binary under test.

pub mod layout;
