//! Pictures: stick-figure strips and animated GIFs of motions and line plots, with no system
//! dependencies.

mod animation;
mod draw;
mod error;
mod font;
mod layout;
mod plot;
mod strip;

pub use animation::{motion_gif, GifOptions};
pub use error::RenderError;
pub use layout::StripRow;
pub use plot::{line_plot, Series};
pub use strip::motion_strip;
