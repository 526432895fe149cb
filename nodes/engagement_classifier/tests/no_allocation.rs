//! The per-frame path (classify + aggregate + emit) must not allocate once sources are known:
//! a counting global allocator watches this thread while 4 cameras stream 30 fps for 60 s.
// Observing allocations needs a GlobalAlloc, which is an unsafe trait; test-only.
#![allow(unsafe_code)]

use engagement_classifier::{
    EngagementClassifierParams, EngagementEstimator, EngagementModel, EngagementSecond, FaceFrame,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

fn note() {
    if ARMED.with(Cell::get) {
        COUNT.with(|c| c.set(c.get() + 1));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn streaming_frames_does_not_allocate() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/synthetic_engagement.json");
    let model = EngagementModel::load(&path).expect("model loads");
    let params = EngagementClassifierParams::default();
    let mut est =
        EngagementEstimator::new(model, params.min_confidence, params.aggregator_config());
    let mut seconds = 0usize;
    let mut emit = |_: &EngagementSecond| seconds += 1;
    let mut features = [0f32; 32];
    let mut run = |est: &mut EngagementEstimator,
                   from: i64,
                   to: i64,
                   emit: &mut dyn FnMut(&EngagementSecond)| {
        for k in from..to {
            for camera in 0..4u32 {
                features[4] = ((k % 97) as f32 - 48.0) / 60.0; // pose_Ry sweeps
                features[30] = ((k % 13) as f32 - 6.0) / 20.0;
                let frame = FaceFrame {
                    stamp_ns: k * 1_000_000_000 / 30 + i64::from(camera) * 3_000_000,
                    source: camera,
                    detection_success: k % 50 != 0,
                    confidence: 0.9,
                    features: &features,
                };
                let mut e = |s: &EngagementSecond| emit(s);
                est.on_frame(&frame, &mut e).expect("valid frame");
            }
        }
    };
    run(&mut est, 0, 30, &mut emit); // first second: the 4 sources register
    ARMED.with(|a| a.set(true));
    run(&mut est, 30, 30 * 61, &mut emit);
    ARMED.with(|a| a.set(false));
    let allocations = COUNT.with(Cell::get);
    assert_eq!(allocations, 0, "allocations while streaming 7200 frames");
    assert!(seconds >= 4 * 59, "{seconds} seconds reported");
}
