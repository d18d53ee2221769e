//! The online estimator allocates nothing per sample (issue 18): a counting global allocator
//! around 100 000 updates and reads of θ̂ and its standard errors. Its own binary, since the
//! allocator is global.

// A global allocator is an unsafe trait: this test binary alone implements one.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use wheelid::online::{OnlineForm, OnlineSettings, OnlineTheta, Split};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is passed on to the system allocator unchanged; the counter is atomic.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: the caller's layout, as GlobalAlloc::alloc requires.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: ptr came from System.alloc with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: as GlobalAlloc::realloc requires, passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn an_update_allocates_nothing() {
    let mut sum = 0.0;
    // The split free (instruments) and fixed by the stamping (three-parameter regressions: the
    // output-error form, the default, and the instruments).
    let fixed = OnlineSettings {
        split: Some(Split::WindowAverage),
        ..OnlineSettings::default()
    };
    let instruments = OnlineSettings {
        form: OnlineForm::InstrumentalVariables,
        ..fixed
    };
    let mut after = 0;
    for (settings, form) in [
        (OnlineSettings::default(), OnlineForm::InstrumentalVariables),
        (fixed, OnlineForm::OutputError),
        (instruments, OnlineForm::InstrumentalVariables),
    ] {
        let mut est = OnlineTheta::new(settings, 0.02).expect("settings");
        // A first-order robot (time constants 50 and 60 ms, unit gains) under held commands,
        // so that θ̂ maps and each form runs after its warm-up.
        let (a_v, a_w) = ((-0.02f64 / 0.05).exp(), (-0.02f64 / 0.06).exp());
        let (mut v, mut w) = (0.0, 0.0);
        let before = ALLOCATIONS.load(Ordering::SeqCst);
        for k in 0..100_000 {
            let t = k as f64 * 0.02;
            let (u, r) = (
                0.3 + 0.2 * (0.7 * t).sin(),
                (1.9 * t).cos() + 0.5 * (5.3 * t).sin(),
            );
            // Stamps jittered by up to 10 % of the period (the jitter correction's path).
            let stamp = t + 0.002 * (1.7 * k as f64).sin();
            let change = est.update(stamp, u, r, v, w);
            sum += est.theta()[0] + est.std_err()[1] + f64::from(u8::from(change.change[0]));
            (v, w) = (a_v * v + (1.0 - a_v) * u, a_w * w + (1.0 - a_w) * r);
        }
        after = ALLOCATIONS.load(Ordering::SeqCst);
        assert_eq!(after - before, 0, "allocations in 100 000 updates");
        // The form ran: both channels map to θ past their warm-up.
        assert!(est.settled(), "{:?}: θ̂ {:?}", est.form(), est.theta());
        assert_eq!(est.form(), form);
    }
    // Checks the counter counts: a Vec allocates.
    let v = std::hint::black_box(vec![sum; 3]);
    assert!(ALLOCATIONS.load(Ordering::SeqCst) > after, "{}", v.len());
}
