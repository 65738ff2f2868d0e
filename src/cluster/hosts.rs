//! Each rank's host name and vector units, gathered on rank 0, and the
//! lines that name them.

use mpi::topology::{Communicator, SimpleCommunicator};

/// Each rank's host name, gathered on rank 0 (by rank; empty elsewhere).
/// Every rank calls it once at start-up, before the roles part.
pub fn rank_hosts(world: &SimpleCommunicator) -> Vec<String> {
    gather_names::<64>(world, &hostname())
}

/// Each rank's `vector_units`, gathered on rank 0 like `rank_hosts`.
pub fn rank_vector_units(world: &SimpleCommunicator) -> Vec<String> {
    gather_names::<16>(world, vector_units())
}

/// `own` from every rank (cut to LEN bytes), by rank on rank 0; empty on
/// the others. A collective: every rank calls it at the same point.
fn gather_names<const LEN: usize>(world: &SimpleCommunicator, own: &str) -> Vec<String> {
    use mpi::collective::Root;
    let mut name = [0u8; LEN];
    let n = own.len().min(LEN);
    name[..n].copy_from_slice(&own.as_bytes()[..n]);
    let root = world.process_at_rank(0);
    if world.rank() != 0 {
        root.gather_into(&name[..]);
        return Vec::new();
    }
    let mut all = vec![0u8; LEN * world.size() as usize];
    root.gather_into_root(&name[..], &mut all[..]);
    all.chunks(LEN)
        .map(|c| {
            let end = c.iter().position(|&b| b == 0).unwrap_or(LEN);
            String::from_utf8_lossy(&c[..end]).into_owned()
        })
        .collect()
}

/// The widest vector instructions of this CPU among those faer's kernels
/// choose between when they run (its products: AVX-512, AVX2 with FMA, or
/// SSE2). Two ranks whose CPUs differ here may round a supernodal or dense
/// factorisation differently (`docs/architecture.md`, *Determinism*).
pub fn vector_units() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            "avx512f"
        } else if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            "avx2+fma"
        } else {
            "sse2"
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::env::consts::ARCH
    }
}

/// A warning, when the ranks' CPUs differ in `vector_units`: results may
/// then depend on where each task ran. Rank 0 prints it at start-up and
/// `summary.json` keeps it in `notes`.
pub fn mixed_vector_units_line(units: &[String]) -> Option<String> {
    let groups = ranks_by(units);
    (groups.len() > 1).then(|| {
        format!(
            "warning: the ranks' CPUs differ in vector units ({}); faer's \
             factorisations choose their code by them, so a run whose contact \
             systems reach those (large dense blocks, as the pyramid's) can end \
             on another state hash than on PCs of one kind (docs/architecture.md, \
             Determinism)",
            groups_text(&groups)
        )
    })
}

/// Ranks grouped by their value, in order of first appearance.
fn ranks_by(values: &[String]) -> Vec<(&str, Vec<usize>)> {
    let mut groups: Vec<(&str, Vec<usize>)> = Vec::new();
    for (rank, value) in values.iter().enumerate() {
        match groups.iter_mut().find(|(v, _)| v == value) {
            Some((_, ranks)) => ranks.push(rank),
            None => groups.push((value, vec![rank])),
        }
    }
    groups
}

/// "value: 0, 1; other: 2".
fn groups_text(groups: &[(&str, Vec<usize>)]) -> String {
    let parts: Vec<String> = groups
        .iter()
        .map(|(v, ranks)| {
            let r: Vec<String> = ranks.iter().map(|r| r.to_string()).collect();
            format!("{v}: {}", r.join(", "))
        })
        .collect();
    parts.join("; ")
}

/// Which ranks run on which host, in one line, when they run on more than
/// one: rank 0 prints it at start-up, so that a job mpirun ends for a lost
/// host (its message names the host, not the ranks) says whose ranks they were.
pub fn hosts_line(hosts: &[String]) -> Option<String> {
    let groups = ranks_by(hosts);
    (groups.len() > 1).then(|| format!("ranks by host: {}", groups_text(&groups)))
}

/// This machine's host name (its UTS name: a lab's "PC" has its own).
pub fn hostname() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: `buf` is writable for its length; gethostname NUL-terminates
    // names shorter than it.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if rc != 0 {
        return "unknown".into();
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    String::from_utf8_lossy(&buf[..end]).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn mixed_vector_units_are_named_by_rank_and_one_kind_says_nothing() {
        assert_eq!(mixed_vector_units_line(&names(&["avx2+fma"; 3])), None);
        assert_eq!(mixed_vector_units_line(&names(&["sse2"])), None);
        let line = mixed_vector_units_line(&names(&["avx2+fma", "sse2", "avx2+fma", "avx512f"]))
            .expect("mixed CPUs are reported");
        assert!(line.starts_with("warning: "), "{line}");
        assert!(
            line.contains("(avx2+fma: 0, 2; sse2: 1; avx512f: 3)"),
            "{line}"
        );
        assert!(!line.contains('\n'), "one line: {line}");
    }

    #[test]
    fn hosts_line_groups_ranks_by_host() {
        assert_eq!(hosts_line(&names(&["pc1", "pc1"])), None);
        assert_eq!(
            hosts_line(&names(&["pc1", "pc2", "pc1"])).as_deref(),
            Some("ranks by host: pc1: 0, 2; pc2: 1")
        );
    }

    #[test]
    fn this_cpu_has_a_known_name() {
        assert!(
            ["avx512f", "avx2+fma", "sse2"].contains(&vector_units())
                || !cfg!(target_arch = "x86_64")
        );
    }
}
