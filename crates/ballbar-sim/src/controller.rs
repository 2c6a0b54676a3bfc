//! The controllers `simulate --compensation DIR` can run a machine with, each emulated from its
//! own documentation ([`crate::linuxcnc`], [`crate::siemens`], [`crate::fanuc`],
//! [`crate::heidenhain`]), and which one a folder's files are for.

use ballbar_model::Axis;

use crate::fanuc::Fanuc;
use crate::heidenhain::Heidenhain;
use crate::linuxcnc::LinuxCnc;
use crate::siemens::Siemens;

/// A controller's compensation as the machine sees it: a trim added to the commanded position of
/// an axis, by position and direction of motion.
pub trait JointTrims: Sync {
    /// Whether `axis` is compensated.
    fn has(&self, axis: Axis) -> bool;
    /// The trim at commanded position `q` (mm) of `axis` moving up (`forward`) or down, mm.
    fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64;
    /// What cross-axis tables add to the commanded position of `output`, mm, at the commanded
    /// positions `commanded[axis.index()]` of every axis; 0 for a controller without them.
    fn cross(&self, _output: Axis, _commanded: &[f64; 6]) -> f64 {
        0.0
    }
    /// The servo period, s: the commanded velocity is the command's change over it.
    fn servo_period_s(&self) -> f64 {
        1e-3
    }
    /// The correction an axis holds at `q` (mm) when a run starts, before it moves in the run:
    /// the machine was positioned there before the test, so the controller applies the trim
    /// that positioning move left, whichever axis the run then moves. The simulated machine
    /// takes the backlash of an axis at rest at the middle of its play (direction 0,
    /// `ballbar_model::term`), so the trim that matches it is the mean of the two directions'
    /// (a positioning move from either side leaves the play and the trim's backlash half
    /// cancelling alike); a table's position error is the same either way. Without it an axis
    /// the run never moves (X in a YZ circle) would run uncompensated: an out-of-plane offset
    /// `d` reads through the bar as `d²/2R`, a radius change of that plane alone, which a fit
    /// with the bar length fixed puts into the scales (`docs/compensation.md`).
    fn positioned(&self, axis: Axis, q: f64) -> f64 {
        0.5 * (self.trim(axis, q, true) + self.trim(axis, q, false))
    }
    /// One servo cycle: the correction after it, from the commanded position `q`, the sign of
    /// the commanded velocity and the correction `previous` before it ([`Self::positioned`]
    /// before the axis moves in the run): the trim of the direction of motion, and at rest
    /// the previous one. LinuxCNC's `compute_screw_comp()` does exactly this.
    fn servo_cycle(&self, axis: Axis, q: f64, velocity: f64, previous: f64) -> f64 {
        if velocity > 0.0 {
            self.trim(axis, q, true)
        } else if velocity < 0.0 {
            self.trim(axis, q, false)
        } else {
            previous
        }
    }
}

impl JointTrims for LinuxCnc {
    fn has(&self, axis: Axis) -> bool {
        LinuxCnc::has(self, axis)
    }
    fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        LinuxCnc::trim(self, axis, q, forward)
    }
    fn servo_period_s(&self) -> f64 {
        LinuxCnc::servo_period_s(self)
    }
    fn servo_cycle(&self, axis: Axis, q: f64, velocity: f64, previous: f64) -> f64 {
        LinuxCnc::servo_cycle(self, axis, q, velocity, previous)
    }
}

impl JointTrims for Siemens {
    fn has(&self, axis: Axis) -> bool {
        Siemens::has(self, axis)
    }
    fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        Siemens::trim(self, axis, q, forward)
    }
    fn cross(&self, output: Axis, commanded: &[f64; 6]) -> f64 {
        Siemens::cross(self, output, commanded)
    }
}

impl JointTrims for Fanuc {
    fn has(&self, axis: Axis) -> bool {
        Fanuc::has(self, axis)
    }
    fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        Fanuc::trim(self, axis, q, forward)
    }
}

impl JointTrims for Heidenhain {
    fn has(&self, axis: Axis) -> bool {
        Heidenhain::has(self, axis)
    }
    fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        Heidenhain::trim(self, axis, q, forward)
    }
    fn cross(&self, output: Axis, commanded: &[f64; 6]) -> f64 {
        Heidenhain::cross(self, output, commanded)
    }
}

/// One of the emulated controllers.
#[derive(Clone, Debug, PartialEq)]
pub enum Controller {
    /// LinuxCNC (`linuxcnc.ini`).
    LinuxCnc(LinuxCnc),
    /// SINUMERIK (`*.INI`, `*.MPF`, `*.SPF` programs setting `$AA_ENC_COMP`, `$MA_...`).
    Siemens(Siemens),
    /// FANUC (a parameter file, `.DAT`).
    Fanuc(Fanuc),
    /// HEIDENHAIN (`*.CMA` assigning `*.COM` tables).
    Heidenhain(Heidenhain),
}

/// Which controller a folder's files are for, from their names: `linuxcnc.ini` is LinuxCNC's;
/// a parameter file `.DAT` FANUC's; an assignment table `.CMA` HEIDENHAIN's; NC programs and INI files (`.INI`, `.MPF`, `.SPF`, upper
/// case, as a SINUMERIK names them) Siemens's; `None` for none of them.
pub fn kind_of(names: &[String]) -> Option<&'static str> {
    if names.iter().any(|n| n == "linuxcnc.ini") {
        return Some("linuxcnc");
    }
    if names.iter().any(|n| n.ends_with(".DAT")) {
        return Some("fanuc");
    }
    if names.iter().any(|n| n.ends_with(".CMA")) {
        return Some("heidenhain");
    }
    let nc = |n: &String| [".INI", ".MPF", ".SPF"].iter().any(|e| n.ends_with(e));
    names.iter().any(nc).then_some("siemens")
}

impl Controller {
    /// The span of `axis`'s own table, mm (LinuxCNC's: `None`, its tables are read as
    /// `ballbar-compensate`'s existing configuration); `None` without one.
    pub fn span(&self, axis: Axis) -> Option<[f64; 2]> {
        match self {
            Controller::LinuxCnc(_) => None,
            Controller::Siemens(c) => c.span(axis),
            Controller::Fanuc(c) => c.span(axis),
            Controller::Heidenhain(c) => c.span(axis),
        }
    }

    /// The cross-axis tables, `(input, output, span of the input, mm)`.
    pub fn cross_tables(&self) -> Vec<(Axis, Axis, [f64; 2])> {
        match self {
            Controller::Siemens(c) => c.cross_tables(),
            Controller::Heidenhain(c) => c.cross_tables(),
            _ => Vec::new(),
        }
    }

    /// What the cross-axis tables of `input` add to `output`'s commanded position at `input`'s
    /// position `q`, mm.
    pub fn cross_of(&self, input: Axis, output: Axis, q: f64) -> f64 {
        match self {
            Controller::Siemens(c) => c.cross_of(input, output, q),
            Controller::Heidenhain(c) => c.cross_of(input, output, q),
            _ => 0.0,
        }
    }
}

impl JointTrims for Controller {
    fn has(&self, axis: Axis) -> bool {
        match self {
            Controller::LinuxCnc(c) => c.has(axis),
            Controller::Siemens(c) => c.has(axis),
            Controller::Fanuc(c) => c.has(axis),
            Controller::Heidenhain(c) => c.has(axis),
        }
    }
    fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        match self {
            Controller::LinuxCnc(c) => c.trim(axis, q, forward),
            Controller::Siemens(c) => c.trim(axis, q, forward),
            Controller::Fanuc(c) => c.trim(axis, q, forward),
            Controller::Heidenhain(c) => c.trim(axis, q, forward),
        }
    }
    fn cross(&self, output: Axis, commanded: &[f64; 6]) -> f64 {
        match self {
            Controller::LinuxCnc(c) => JointTrims::cross(c, output, commanded),
            Controller::Siemens(c) => JointTrims::cross(c, output, commanded),
            Controller::Fanuc(c) => JointTrims::cross(c, output, commanded),
            Controller::Heidenhain(c) => JointTrims::cross(c, output, commanded),
        }
    }
    fn servo_period_s(&self) -> f64 {
        match self {
            Controller::LinuxCnc(c) => JointTrims::servo_period_s(c),
            Controller::Siemens(c) => JointTrims::servo_period_s(c),
            Controller::Fanuc(c) => JointTrims::servo_period_s(c),
            Controller::Heidenhain(c) => JointTrims::servo_period_s(c),
        }
    }
    fn servo_cycle(&self, axis: Axis, q: f64, velocity: f64, previous: f64) -> f64 {
        match self {
            Controller::LinuxCnc(c) => JointTrims::servo_cycle(c, axis, q, velocity, previous),
            Controller::Siemens(c) => JointTrims::servo_cycle(c, axis, q, velocity, previous),
            Controller::Fanuc(c) => JointTrims::servo_cycle(c, axis, q, velocity, previous),
            Controller::Heidenhain(c) => JointTrims::servo_cycle(c, axis, q, velocity, previous),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The controller the simulator is handed applies its own servo period and cycle: a
    /// LinuxCNC's `[EMCMOT] SERVO_PERIOD` reaches the simulation through the enum.
    #[test]
    fn the_enum_forwards_the_servo_period_and_cycle() {
        let ini = "[EMCMOT]\nSERVO_PERIOD = 250000\n[JOINT_0]\nBACKLASH = 0.004\n";
        let inner = LinuxCnc::parse(ini, "m.ini", &|_| Err(String::new())).unwrap();
        let c = Controller::LinuxCnc(inner.clone());
        assert!((JointTrims::servo_period_s(&c) - 2.5e-4).abs() < 1e-18);
        for (v, prev) in [(1.0, 0.0), (-1.0, 0.002), (0.0, 0.002), (0.0, -0.002)] {
            assert_eq!(
                JointTrims::servo_cycle(&c, Axis::X, 10.0, v, prev),
                inner.servo_cycle(Axis::X, 10.0, v, prev)
            );
        }
    }
}
