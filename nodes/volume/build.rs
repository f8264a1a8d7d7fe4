fn main() {
    relume_build::register_nodes();
}
