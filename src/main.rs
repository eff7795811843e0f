fn main() {
    std::process::exit(wgsph::cli::main());
}
