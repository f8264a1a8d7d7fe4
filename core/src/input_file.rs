//! Reading the files a person names, refusing what is not a regular file.

/// Reads a file a person named (a graph, a scene, a mesh, an image, a file parameter): only a
/// regular file, so that a path naming a device (`/dev/zero`), a FIFO or a folder is an error
/// at once instead of a hang or an endless read.
pub fn read_input(path: &std::path::Path) -> std::io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        let what = if meta.is_dir() { "a folder" } else { "not a regular file (a device or a pipe)" };
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("it is {what}")));
    }
    std::fs::read(path)
}
