fn main() {
    std::process::exit(wgsph::app::main());
}
