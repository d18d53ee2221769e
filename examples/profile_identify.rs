//! Times the stages of `identify` on a 1,000,000-row simulated recording (a rough profile; the
//! benchmark is `cargo bench --bench identify`).
use std::time::Instant;
use wheelid::core::condition::{self, ConditionSettings};
use wheelid::core::{DynamicModel, RegressorModel};
use wheelid::models::VwPd;
use wheelid::robots::{Excitation, RobotProfile, SimSettings, simulate_recording};

fn main() {
    let robot = RobotProfile::pioneer3dx();
    let settings = SimSettings {
        duration_s: 99_999.95,
        substeps: 4,
        ..SimSettings::default()
    };
    let rec =
        simulate_recording(&robot, &Excitation::thesis_pioneer(), &settings).expect("simulates");
    let t = Instant::now();
    let (u, _) = condition::make_uniform(&rec).expect("uniform");
    println!("make_uniform {:?}", t.elapsed());
    let t = Instant::now();
    let (fc, _) = condition::suggest_cutoff(&[&u]).expect("cutoff");
    println!("cutoff {:?}", t.elapsed());
    let t = Instant::now();
    let c = condition::condition(&u, None, fc, &ConditionSettings::default()).expect("condition");
    println!("condition {:?}", t.elapsed());
    let t = Instant::now();
    let x = c.smooth(c.v()).expect("smooth");
    println!("one sosfiltfilt {:?}", t.elapsed());
    let t = Instant::now();
    let regs = VwPd.regression(&c).expect("reg");
    println!("regression {:?}", t.elapsed());
    let t = Instant::now();
    let sim = VwPd.simulate(&robot.theta, &u, &[x[0], 0.0]).expect("sim");
    println!("simulate {:?}", t.elapsed());
    let t = Instant::now();
    let svd = regs[0].x.clone().svd(true, true);
    println!(
        "svd {:?} {}",
        t.elapsed(),
        svd.singular_values[0] + sim[0][0]
    );
}
