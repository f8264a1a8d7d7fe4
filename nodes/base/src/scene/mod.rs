//! Scenes: the file format, OBJ loading, analytic shapes, mesh subdivision, environment maps, and the scene
//! nodes: LoadScene, MoveObject, DeformMesh, OrbitCamera, TurnEnvironment, ReplaceEnvironment.

pub mod builder;
pub mod deform_mesh;
pub mod envmap;
pub mod format;
pub mod load_scene;
pub mod move_object;
pub mod obj;
pub mod orbit_camera;
pub mod replace_environment;
pub mod shapes;
pub mod subdivide;
pub mod turn_environment;
