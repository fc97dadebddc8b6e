//! What `rally batch` prints and writes: the summary table, standings and the CSV.

use super::*;

pub(super) fn name_of(names: &HashMap<i64, String>, id: Option<i64>) -> String {
    id.and_then(|i| names.get(&i).cloned())
        .unwrap_or_else(|| id.map_or("?".into(), |i| format!("#{i}")))
}

pub(super) fn write_csv(
    path: &Path,
    order: &[i64],
    rows: &HashMap<i64, wire::Match>,
    names: &HashMap<i64, String>,
) -> anyhow::Result<()> {
    let mut w = csv::Writer::from_path(path)?;
    w.write_record([
        "match_id",
        "tournament_id",
        "agent_a",
        "agent_b",
        "status",
        "rallies",
        "seed",
        "points_a",
        "points_b",
        "mean_rally_length",
        "max_rally_length",
        "in_box_fraction",
        "energy_distance",
        "drift_slope",
        "sim_version",
        "preset",
        "error",
    ])?;
    fn opt<T: ToString>(v: Option<T>) -> String {
        v.map_or(String::new(), |x| x.to_string())
    }
    for id in order {
        let Some(m) = rows.get(id) else { continue };
        w.write_record([
            id.to_string(),
            opt(m.tournament_id),
            name_of(names, Some(m.agent_a)),
            name_of(names, Some(m.agent_b)),
            m.status.to_string(),
            m.rallies.to_string(),
            m.seed.to_string(),
            opt(m.points_a),
            opt(m.points_b),
            opt(m.mean_rally_length),
            opt(m.max_rally_length),
            opt(m.in_box_fraction),
            opt(m.energy_distance),
            opt(m.drift_slope),
            m.sim_version.clone(),
            m.preset.clone(),
            opt(m.error.clone()),
        ])?;
    }
    w.flush()?;
    Ok(())
}

/// Per agent over the batch's finished matches: matches, wins/draws/losses, points, mean rally length.
pub(super) fn print_summary(
    order: &[i64],
    rows: &HashMap<i64, wire::Match>,
    names: &HashMap<i64, String>,
) {
    #[derive(Default)]
    struct Line {
        record: wire::Record,
        rally_sum: f64,
    }
    let mut lines: HashMap<i64, Line> = HashMap::new();
    for id in order {
        let Some(m) = rows.get(id) else { continue };
        let (a, b) = (m.agent_a, m.agent_b);
        let (Some(pa), Some(pb)) = (m.points_a, m.points_b) else {
            continue;
        };
        let mean = m.mean_rally_length.unwrap_or(0.0);
        for (me, won, lost) in [(a, pa, pb), (b, pb, pa)] {
            let x = lines.entry(me).or_default();
            x.record.add(won, lost);
            x.rally_sum += mean;
        }
    }
    let mut sorted: Vec<(i64, Line)> = lines.into_iter().collect();
    let pct = |l: &Line| l.record.points_won_pct().unwrap_or(0.0);
    sorted.sort_by(|x, y| pct(&y.1).total_cmp(&pct(&x.1)).then(x.0.cmp(&y.0)));
    println!();
    println!(
        "{:<24} {:>7} {:>4} {:>4} {:>4} {:>7} {:>7} {:>8} {:>11}",
        "agent", "matches", "W", "D", "L", "points", "lost", "won %", "mean rally"
    );
    for (id, l) in &sorted {
        println!(
            "{:<24} {:>7} {:>4} {:>4} {:>4} {:>7} {:>7} {:>7.1}% {:>11.2}",
            name_of(names, Some(*id)),
            l.record.matches,
            l.record.wins,
            l.record.draws,
            l.record.losses,
            l.record.points_for,
            l.record.points_against,
            pct(l),
            l.rally_sum / l.record.matches.max(1) as f64
        );
    }
}

/// A tournament's standings and cross-table (points won–lost), as the server computed them.
pub(super) fn print_standings(id: i64, label: &str, v: &wire::TournamentView) {
    println!();
    println!("tournament {id}: {label}");
    let agents = &v.cross_table_agents;
    print!("{:<24}", "");
    for k in 0..agents.len() {
        print!(" {:>9}", format!("[{}]", k + 1));
    }
    println!("   place");
    for (i, name) in agents.iter().enumerate() {
        print!("{:<24}", format!("[{}] {name}", i + 1));
        for j in 0..agents.len() {
            let cell = match v.cross_table.get(i).and_then(|row| row.get(j)) {
                Some(Some(c)) => format!("{}-{}", c.points_for, c.points_against),
                _ => "-".to_string(),
            };
            print!(" {cell:>9}");
        }
        let place = v
            .standings
            .iter()
            .find(|s| &s.agent == name)
            .map_or("?".into(), |s| s.place.to_string());
        println!("   {place:>5}");
    }
}

/// An SPRT's outcome: its hypotheses, status, matches, LLR within its bounds and Elo estimate.
pub(super) fn print_sprt(id: i64, label: &str, v: &wire::SprtView) {
    println!();
    println!(
        "sprt {id}: {label}, H0 {} / H1 {} Elo: {} after {} matches, LLR {:+.3} in [{:.3}, {:.3}], Elo estimate {}",
        v.row.elo0,
        v.row.elo1,
        v.row.status,
        v.row.matches_done,
        v.row.llr,
        v.bounds.lower,
        v.bounds.upper,
        v.elo_estimate.map_or("–".into(), |e| format!("{e:+.1}"))
    );
}
