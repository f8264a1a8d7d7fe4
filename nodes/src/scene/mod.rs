//! Scenes: the file format, OBJ loading, analytic shapes, environment maps, and the
//! LoadScene node.

pub mod builder;
pub mod envmap;
pub mod format;
pub mod load_scene;
pub mod move_object;
pub mod obj;
pub mod shapes;

use relume_core::Registry;

pub fn register(reg: &mut Registry) {
    reg.add::<load_scene::LoadScene>();
    reg.add::<move_object::MoveObject>();
}
