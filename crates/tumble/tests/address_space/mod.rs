//! The address-space cap of the host-memory tests (`particle_host_memory.rs`,
//! `rigid_host_memory.rs`): with RLIMIT_AS set a little above what the process uses, no
//! allocation can succeed lazily under Linux's overcommit and be killed when touched.

/// The process' address space now (bytes), from /proc/self/status, once every worker of
/// rayon's pool has run: a worker that the OS had not started yet would map its signal stack
/// after the cap and abort the process (seen once, on a loaded 2-core machine).
pub fn address_space() -> u64 {
    rayon::broadcast(|_| ());
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let line = status
        .lines()
        .find_map(|line| line.strip_prefix("VmSize:"))
        .expect("a VmSize line");
    let kilobytes: u64 = line.trim().trim_end_matches("kB").trim().parse().unwrap();
    kilobytes * 1024
}

/// Sets the soft address-space limit (bytes) and returns the previous limits.
pub fn limit_address_space(bytes: u64) -> libc::rlimit {
    let mut previous = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit and setrlimit read and write the rlimit passed; the caller's file
    // holds one test, so no other thread of the process allocates meanwhile.
    unsafe {
        assert_eq!(libc::getrlimit(libc::RLIMIT_AS, &mut previous), 0);
        let capped = libc::rlimit {
            rlim_cur: bytes.min(previous.rlim_max),
            rlim_max: previous.rlim_max,
        };
        assert_eq!(libc::setrlimit(libc::RLIMIT_AS, &capped), 0);
    }
    previous
}
