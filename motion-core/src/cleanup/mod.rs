//! Contact-aware clean-up of a finished motion, as animation tools do it: planted feet are held
//! where they were planted and put on the floor, the legs re-solved by two-bone IK
//! ([`foot_lock`]). It runs on every method's output after generation and can be switched off;
//! reports give the figures before and after it.

mod foot_lock;
mod leg_ik;

pub use foot_lock::{foot_lock, FootLockConfig, FootLockReport};
pub use leg_ik::solve_leg;
