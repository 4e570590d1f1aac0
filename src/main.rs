fn main() {
    std::process::exit(granular::cli::main());
}
