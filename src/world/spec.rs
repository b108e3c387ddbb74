//! Which rank of which world this process is: from `train`'s flags (`--rank`, `--world-size`,
//! `--local-rank`, `--rendezvous host:port`), else torchrun's variables (`RANK`, `WORLD_SIZE`,
//! `LOCAL_RANK`, `MASTER_ADDR`, `MASTER_PORT`), else Slurm's (`SLURM_PROCID`, `SLURM_NTASKS`,
//! `SLURM_LOCALID`, the job's node list), else none: one process.

use super::error::WorldError;

/// Most processes one world may have.
pub const MAX_WORLD: usize = 4096;

/// Slurm sets no port: without `MASTER_PORT` every rank of a job takes this plus the job id
/// modulo [`SLURM_PORT_SPAN`], the same number on every rank and different for most pairs of
/// jobs sharing a node.
pub const SLURM_BASE_PORT: u16 = 29500;
pub const SLURM_PORT_SPAN: u64 = 10000;

/// Where a world's facts came from (messages name it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorldSource {
    Flags,
    Torchrun,
    Slurm,
}

impl WorldSource {
    fn names(self) -> &'static str {
        match self {
            WorldSource::Flags => "--rank, --world-size and --rendezvous",
            WorldSource::Torchrun => "RANK, WORLD_SIZE, LOCAL_RANK, MASTER_ADDR and MASTER_PORT",
            WorldSource::Slurm => {
                "SLURM_PROCID, SLURM_NTASKS, SLURM_LOCALID and SLURM_JOB_NODELIST (MASTER_ADDR and MASTER_PORT override the host and port)"
            }
        }
    }
}

/// Rank 0's host and port, where the other ranks join.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RendezvousAddress {
    pub host: String,
    pub port: u16,
}

impl std::fmt::Display for RendezvousAddress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.host, self.port)
    }
}

/// `train`'s world flags, as given.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WorldFlags {
    pub rank: Option<usize>,
    pub world_size: Option<usize>,
    pub local_rank: Option<usize>,
    /// `host:port`.
    pub rendezvous: Option<String>,
}

impl WorldFlags {
    fn any(&self) -> bool {
        self.rank.is_some()
            || self.world_size.is_some()
            || self.local_rank.is_some()
            || self.rendezvous.is_some()
    }
}

/// This process's place in a world of processes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WorldSpec {
    pub rank: usize,
    pub size: usize,
    /// This process's GPU among its host's (torchrun's `LOCAL_RANK`, Slurm's `SLURM_LOCALID`;
    /// with the flags `--local-rank`, else the rank).
    pub local_rank: usize,
    pub rendezvous: RendezvousAddress,
    pub source: WorldSource,
}

impl WorldSpec {
    /// The world `flags` describe, else the one the environment's variables (read by `var`)
    /// describe, else None: this process trains alone. Every inconsistency is one line that
    /// names the flag or variable.
    ///
    /// From the environment, a world of one process is no world (a launcher's single task
    /// trains as a plain run), and Slurm's variables count only in a job step that `srun`
    /// launched (`SLURM_STEP_ID` set): a batch script of a job of several tasks has
    /// `SLURM_NTASKS` too, and a `train` run there directly is one process, not rank 0 of a
    /// world waiting for ranks that never come.
    pub fn resolve(
        flags: &WorldFlags,
        var: impl Fn(&str) -> Option<String>,
    ) -> Result<Option<WorldSpec>, WorldError> {
        if flags.any() {
            return from_flags(flags).map(Some);
        }
        let spec = if var("RANK").is_some() || var("WORLD_SIZE").is_some() {
            from_torchrun(&var)?
        } else if var("SLURM_PROCID").is_some()
            && var("SLURM_NTASKS").is_some()
            && var("SLURM_STEP_ID").is_some()
        {
            from_slurm(&var)?
        } else {
            return Ok(None);
        };
        Ok((spec.size > 1).then_some(spec))
    }

    /// Whether this process is rank 0 (it hosts the rendezvous, evaluates and checkpoints).
    pub fn is_leader(&self) -> bool {
        self.rank == 0
    }

    fn checked(self) -> Result<WorldSpec, WorldError> {
        let names = self.source.names();
        if self.size == 0 || self.size > MAX_WORLD {
            return Err(WorldError::Spec(format!(
                "a world of {} processes ({names}): give 1 to {MAX_WORLD}",
                self.size
            )));
        }
        if self.rank >= self.size {
            return Err(WorldError::Spec(format!(
                "rank {} in a world of {} processes ({names}): ranks are 0 to {}",
                self.rank,
                self.size,
                self.size - 1
            )));
        }
        if self.rendezvous.host.is_empty() {
            return Err(WorldError::Spec(format!(
                "no rendezvous host ({names}): name rank 0's host"
            )));
        }
        Ok(self)
    }
}

fn from_flags(flags: &WorldFlags) -> Result<WorldSpec, WorldError> {
    let missing: Vec<&str> = [
        ("--rank", flags.rank.is_none()),
        ("--world-size", flags.world_size.is_none()),
        ("--rendezvous host:port", flags.rendezvous.is_none()),
    ]
    .into_iter()
    .filter(|&(_, missing)| missing)
    .map(|(name, _)| name)
    .collect();
    let (Some(rank), Some(size), Some(address)) = (flags.rank, flags.world_size, &flags.rendezvous)
    else {
        return Err(WorldError::Spec(format!(
            "one rank of a world of processes needs --rank, --world-size and --rendezvous host:port; missing {}",
            missing.join(", ")
        )));
    };
    WorldSpec {
        rank,
        size,
        local_rank: flags.local_rank.unwrap_or(rank),
        rendezvous: parse_address(address, "--rendezvous")?,
        source: WorldSource::Flags,
    }
    .checked()
}

fn from_torchrun(var: &impl Fn(&str) -> Option<String>) -> Result<WorldSpec, WorldError> {
    let source = WorldSource::Torchrun;
    let host = required(var, "MASTER_ADDR", source)?;
    let mut port = parse_port(&required(var, "MASTER_PORT", source)?, "MASTER_PORT")?;
    // Under torchrun's agent (`TORCHELASTIC_RUN_ID` set) the agent's own store listens on
    // MASTER_PORT: the world takes the next port on rank 0's host.
    if var("TORCHELASTIC_RUN_ID").is_some() {
        port = port.checked_add(1).ok_or_else(|| {
            WorldError::Spec(
                "MASTER_PORT=65535 under torchrun: the world listens on the port after torchrun's (give --master-port below 65535)"
                    .to_owned(),
            )
        })?;
    }
    WorldSpec {
        rank: number(var, "RANK", source)?,
        size: number(var, "WORLD_SIZE", source)?,
        local_rank: number(var, "LOCAL_RANK", source)?,
        rendezvous: RendezvousAddress { host, port },
        source,
    }
    .checked()
}

fn from_slurm(var: &impl Fn(&str) -> Option<String>) -> Result<WorldSpec, WorldError> {
    let source = WorldSource::Slurm;
    let host = match var("MASTER_ADDR") {
        Some(host) => host,
        None => {
            let (name, nodes) = ["SLURM_JOB_NODELIST", "SLURM_NODELIST"]
                .into_iter()
                .find_map(|name| var(name).map(|nodes| (name, nodes)))
                .ok_or_else(|| {
                    WorldError::Spec(
                        "Slurm sets no SLURM_JOB_NODELIST here: set MASTER_ADDR to rank 0's host"
                            .to_owned(),
                    )
                })?;
            first_slurm_host(&nodes).ok_or_else(|| {
                WorldError::Spec(format!(
                    "{name}={nodes:?} is not a node list this reads (e.g. gpu[01-04],login1): set MASTER_ADDR to rank 0's host"
                ))
            })?
        }
    };
    let port = match var("MASTER_PORT") {
        Some(port) => parse_port(&port, "MASTER_PORT")?,
        None => {
            let job = number(var, "SLURM_JOB_ID", source).map_err(|_| {
                WorldError::Spec(
                    "neither MASTER_PORT nor SLURM_JOB_ID is set: set MASTER_PORT to a free port on rank 0's host"
                        .to_owned(),
                )
            })?;
            SLURM_BASE_PORT + (job as u64 % SLURM_PORT_SPAN) as u16
        }
    };
    WorldSpec {
        rank: number(var, "SLURM_PROCID", source)?,
        size: number(var, "SLURM_NTASKS", source)?,
        local_rank: number(var, "SLURM_LOCALID", source)?,
        rendezvous: RendezvousAddress { host, port },
        source,
    }
    .checked()
}

fn required(
    var: &impl Fn(&str) -> Option<String>,
    name: &str,
    source: WorldSource,
) -> Result<String, WorldError> {
    var(name).filter(|v| !v.trim().is_empty()).ok_or_else(|| {
        WorldError::Spec(format!(
            "{name} is not set: a rank launched this way needs {}",
            source.names()
        ))
    })
}

fn number(
    var: &impl Fn(&str) -> Option<String>,
    name: &str,
    source: WorldSource,
) -> Result<usize, WorldError> {
    let text = required(var, name, source)?;
    text.trim().parse().map_err(|_| {
        WorldError::Spec(format!(
            "{name}={text:?} is not a whole number ≥ 0 ({})",
            source.names()
        ))
    })
}

fn parse_port(text: &str, name: &str) -> Result<u16, WorldError> {
    match text.trim().parse::<u16>() {
        Ok(port) if port > 0 => Ok(port),
        _ => Err(WorldError::Spec(format!(
            "{name}={text:?} is not a port (1 to 65535)"
        ))),
    }
}

/// `host:port` (an IPv6 host in brackets: `[::1]:29500`).
fn parse_address(text: &str, name: &str) -> Result<RendezvousAddress, WorldError> {
    let bad = || {
        WorldError::Spec(format!(
            "{name} {text:?} is not host:port (e.g. node01:29500)"
        ))
    };
    let (host, port) = text.rsplit_once(':').ok_or_else(bad)?;
    let host = host
        .strip_prefix('[')
        .and_then(|h| h.strip_suffix(']'))
        .unwrap_or(host);
    if host.is_empty() {
        return Err(bad());
    }
    Ok(RendezvousAddress {
        host: host.to_owned(),
        port: parse_port(port, name)?,
    })
}

/// The first host of a Slurm node list: `gpu[01-04,07],login1` -> `gpu01`, `a,b` -> `a`,
/// `node[3]` -> `node3` (None for what is not such a list).
pub fn first_slurm_host(nodes: &str) -> Option<String> {
    let nodes = nodes.trim();
    // The first entry: up to the first comma outside brackets.
    let mut depth = 0i32;
    let end = nodes
        .char_indices()
        .find(|&(_, c)| {
            match c {
                '[' => depth += 1,
                ']' => depth -= 1,
                ',' if depth == 0 => return true,
                _ => {}
            }
            false
        })
        .map_or(nodes.len(), |(i, _)| i);
    let entry = &nodes[..end];
    let Some(open) = entry.find('[') else {
        return (!entry.is_empty() && !entry.contains(']')).then(|| entry.to_owned());
    };
    let close = entry.rfind(']').filter(|&c| c > open)?;
    let (prefix, suffix) = (&entry[..open], &entry[close + 1..]);
    let first = entry[open + 1..close].split(',').next()?;
    let first = first.split('-').next()?;
    if prefix.is_empty() || first.is_empty() || !first.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    Some(format!("{prefix}{first}{suffix}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn vars(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let map: HashMap<String, String> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |name| map.get(name).cloned()
    }

    fn message(r: Result<Option<WorldSpec>, WorldError>) -> String {
        let e = r.expect_err("refused").to_string();
        assert!(!e.contains('\n'), "one line: {e}");
        e
    }

    #[test]
    fn no_flag_and_no_variable_is_one_process() {
        let spec = WorldSpec::resolve(&WorldFlags::default(), vars(&[("HOME", "/root")]));
        assert_eq!(spec.expect("fine"), None);
    }

    #[test]
    fn torchrun_variables_give_the_rank_and_the_rendezvous() {
        let spec = WorldSpec::resolve(
            &WorldFlags::default(),
            vars(&[
                ("RANK", "3"),
                ("WORLD_SIZE", "8"),
                ("LOCAL_RANK", "1"),
                ("MASTER_ADDR", "node01"),
                ("MASTER_PORT", "29500"),
            ]),
        )
        .expect("valid")
        .expect("a world");
        assert_eq!(
            spec,
            WorldSpec {
                rank: 3,
                size: 8,
                local_rank: 1,
                rendezvous: RendezvousAddress {
                    host: "node01".into(),
                    port: 29500
                },
                source: WorldSource::Torchrun,
            }
        );
        assert!(!spec.is_leader());
    }

    #[test]
    fn under_torchrun_the_world_takes_the_port_after_the_agents() {
        let spec = WorldSpec::resolve(
            &WorldFlags::default(),
            vars(&[
                ("RANK", "1"),
                ("WORLD_SIZE", "2"),
                ("LOCAL_RANK", "1"),
                ("MASTER_ADDR", "127.0.0.1"),
                ("MASTER_PORT", "29500"),
                ("TORCHELASTIC_RUN_ID", "none"),
            ]),
        )
        .expect("valid")
        .expect("a world");
        assert_eq!(spec.rendezvous.port, 29501);
    }

    #[test]
    fn slurm_variables_take_the_first_node_and_a_port_from_the_job() {
        let spec = WorldSpec::resolve(
            &WorldFlags::default(),
            vars(&[
                ("SLURM_PROCID", "0"),
                ("SLURM_NTASKS", "16"),
                ("SLURM_LOCALID", "0"),
                ("SLURM_STEP_ID", "0"),
                ("SLURM_JOB_NODELIST", "gpu[07-08,11],login1"),
                ("SLURM_JOB_ID", "123456"),
            ]),
        )
        .expect("valid")
        .expect("a world");
        assert_eq!(spec.rendezvous.host, "gpu07");
        assert_eq!(spec.rendezvous.port, 29500 + 3456);
        assert_eq!(
            (spec.rank, spec.size, spec.source),
            (0, 16, WorldSource::Slurm)
        );
        // MASTER_ADDR and MASTER_PORT override Slurm's.
        let spec = WorldSpec::resolve(
            &WorldFlags::default(),
            vars(&[
                ("SLURM_PROCID", "1"),
                ("SLURM_NTASKS", "2"),
                ("SLURM_LOCALID", "1"),
                ("SLURM_STEP_ID", "3"),
                ("SLURM_JOB_NODELIST", "gpu07"),
                ("MASTER_ADDR", "10.0.0.5"),
                ("MASTER_PORT", "4000"),
            ]),
        )
        .expect("valid")
        .expect("a world");
        assert_eq!(spec.rendezvous.to_string(), "10.0.0.5:4000");
    }

    #[test]
    fn a_batch_script_or_a_single_task_is_one_process() {
        // A batch script of a 4-task job: Slurm's variables without a job step.
        let batch = [
            ("SLURM_PROCID", "0"),
            ("SLURM_NTASKS", "4"),
            ("SLURM_LOCALID", "0"),
            ("SLURM_JOB_NODELIST", "gpu07"),
            ("SLURM_JOB_ID", "5"),
        ];
        let spec = WorldSpec::resolve(&WorldFlags::default(), vars(&batch));
        assert_eq!(spec.expect("fine"), None);
        // A launcher's world of one: a plain run.
        let one = [
            ("RANK", "0"),
            ("WORLD_SIZE", "1"),
            ("LOCAL_RANK", "0"),
            ("MASTER_ADDR", "127.0.0.1"),
            ("MASTER_PORT", "29500"),
        ];
        let spec = WorldSpec::resolve(&WorldFlags::default(), vars(&one));
        assert_eq!(spec.expect("fine"), None);
        // The flags ask for it explicitly: a world of one process is one.
        let flags = WorldFlags {
            rank: Some(0),
            world_size: Some(1),
            local_rank: None,
            rendezvous: Some("127.0.0.1:29500".into()),
        };
        let spec = WorldSpec::resolve(&flags, vars(&[])).expect("fine");
        assert_eq!(spec.map(|s| s.size), Some(1));
    }

    #[test]
    fn flags_come_before_the_variables() {
        let flags = WorldFlags {
            rank: Some(1),
            world_size: Some(2),
            local_rank: None,
            rendezvous: Some("[::1]:29501".into()),
        };
        let spec = WorldSpec::resolve(&flags, vars(&[("RANK", "5"), ("WORLD_SIZE", "9")]))
            .expect("valid")
            .expect("a world");
        assert_eq!((spec.rank, spec.size, spec.local_rank), (1, 2, 1));
        assert_eq!(spec.rendezvous.host, "::1");
        assert_eq!(spec.source, WorldSource::Flags);
    }

    #[test]
    fn a_bad_world_is_one_line_naming_the_flag_or_variable() {
        let e = message(WorldSpec::resolve(
            &WorldFlags {
                rank: Some(0),
                ..WorldFlags::default()
            },
            vars(&[]),
        ));
        assert!(
            e.contains("missing --world-size, --rendezvous host:port"),
            "{e}"
        );
        let torchrun = |pairs: &[(&str, &str)]| {
            let mut all = vec![
                ("RANK", "0"),
                ("WORLD_SIZE", "2"),
                ("LOCAL_RANK", "0"),
                ("MASTER_ADDR", "node01"),
                ("MASTER_PORT", "29500"),
            ];
            for &(k, v) in pairs {
                all.retain(|(name, _)| *name != k);
                if !v.is_empty() {
                    all.push((k, v));
                }
            }
            message(WorldSpec::resolve(&WorldFlags::default(), vars(&all)))
        };
        for (change, words) in [
            (("RANK", "2"), "rank 2 in a world of 2 processes"),
            (("RANK", "-1"), "RANK=\"-1\" is not a whole number"),
            (("WORLD_SIZE", "0"), "a world of 0 processes"),
            (
                ("MASTER_PORT", "99999"),
                "MASTER_PORT=\"99999\" is not a port",
            ),
            (("MASTER_ADDR", ""), "MASTER_ADDR is not set"),
            (("LOCAL_RANK", ""), "LOCAL_RANK is not set"),
        ] {
            let e = torchrun(&[change]);
            assert!(e.contains(words), "{change:?}: {e}");
        }
        let e = message(WorldSpec::resolve(
            &WorldFlags {
                rank: Some(0),
                world_size: Some(2),
                local_rank: None,
                rendezvous: Some("node01".into()),
            },
            vars(&[]),
        ));
        assert!(e.contains("is not host:port"), "{e}");
        let e = message(WorldSpec::resolve(
            &WorldFlags::default(),
            vars(&[
                ("SLURM_PROCID", "0"),
                ("SLURM_NTASKS", "2"),
                ("SLURM_LOCALID", "0"),
                ("SLURM_STEP_ID", "0"),
                ("SLURM_JOB_NODELIST", "gpu07"),
            ]),
        ));
        assert!(e.contains("set MASTER_PORT"), "{e}");
    }

    #[test]
    fn slurm_node_lists() {
        for (list, first) in [
            ("gpu[01-04,07],login1", Some("gpu01")),
            ("a,b", Some("a")),
            ("node[3]", Some("node3")),
            ("rack1-n[009-012]-ib", Some("rack1-n009-ib")),
            ("single", Some("single")),
            ("", None),
            ("[1-2]", None),
            ("gpu[a-b]", None),
            ("gpu]1[", None),
        ] {
            assert_eq!(first_slurm_host(list).as_deref(), first, "{list:?}");
        }
    }
}
