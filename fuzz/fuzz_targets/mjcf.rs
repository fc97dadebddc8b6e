//! The MJCF loader on any text: a model or an error, never a panic, a hang or unbounded memory.
//! Every `<include file=…>` resolves to the input itself, so include cycles are exercised too. A
//! model that loads has its tendons evaluated at the reference configuration: finite lengths and
//! moment arms (wrapping included) whenever its numbers are of a physical size.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(model) = sim::mjcf::parse_str(text, "fuzz.xml") {
        tendons_are_finite(&model);
    }
    let _ = sim::mjcf::load(Path::new("fuzz.xml"), &|_: &Path| Ok(text.to_string()));
});

/// Lengths and moment arms at the reference configuration are finite when every position and size
/// in the model is below a kilometre (beyond that squares overflow long before physics matters).
fn tendons_are_finite(model: &sim::model::Model) {
    let physical = |v: &[f64]| v.iter().all(|x| x.abs() < 1e3);
    let sane = model.bodies.iter().all(|b| physical(b.pos.as_slice()))
        && model.sites.iter().all(|s| physical(s.pos.as_slice()))
        && model
            .geoms
            .iter()
            .all(|g| physical(g.pos.as_slice()) && physical(&g.size))
        && model
            .joints
            .iter()
            .all(|j| physical(&[j.reference]) && physical(j.pos.as_slice()));
    if !sane {
        return;
    }
    let kin = sim::kinematics::Kinematics::new(model);
    let mut ten = sim::kinematics::TendonKinematics::new(model);
    ten.update(model, &kin);
    assert!(
        ten.length.iter().all(|l| l.is_finite()),
        "a tendon length is not finite"
    );
    assert!(
        (0..model.tendons.len()).all(|t| ten.moment_arms(t).iter().all(|m| m.is_finite())),
        "a moment arm is not finite"
    );
}
