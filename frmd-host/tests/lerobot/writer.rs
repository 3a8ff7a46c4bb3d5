//! Writes LeRobot datasets (v2.1 and v3.0 layouts) with the `parquet` crate's writer, in the
//! shape pyarrow gives LeRobot's files: vector columns as 3-level LIST of optional float,
//! optional scalars, snappy compression; `meta/info.json` with features and totals, the
//! episodes metadata and the tasks.
use frmd_host::data::lerobot::Layout;
use parquet::basic::Compression;
use parquet::data_type::{FloatType, Int64Type};
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::parser::parse_message_type;
use serde_json::json;
use std::path::Path;
use std::sync::Arc;

/// One frame: its indices, timestamp and one vector per column of [`Lerobot::vector_keys`].
#[derive(Clone, Debug)]
pub struct Row {
    pub episode: i64,
    pub frame: i64,
    pub timestamp: f32,
    pub vectors: Vec<Vec<f32>>,
}

/// A dataset to write.
#[derive(Clone, Debug)]
pub struct Lerobot {
    pub layout: Layout,
    pub fps: f64,
    /// Vector columns, e.g. `observation.state`, `action`.
    pub vector_keys: Vec<String>,
    pub rows: Vec<Row>,
    /// Episode lengths for the episodes metadata instead of the rows' counts.
    pub listed_lengths: Option<Vec<i64>>,
}

impl Lerobot {
    /// Episodes of the given lengths at `fps` with `dims` values per vector column; value
    /// `(episode, frame, column, element)` is a smooth function of all four.
    pub fn synthetic(
        layout: Layout,
        fps: f64,
        lengths: &[usize],
        columns: &[(&str, usize)],
    ) -> Self {
        let mut rows = Vec::new();
        for (e, &len) in lengths.iter().enumerate() {
            for f in 0..len {
                let vectors = columns
                    .iter()
                    .enumerate()
                    .map(|(c, &(_, dim))| {
                        (0..dim)
                            .map(|i| ((e * 7 + f) as f32 * 0.05 + c as f32 + i as f32 * 0.3).sin())
                            .collect()
                    })
                    .collect();
                rows.push(Row {
                    episode: e as i64,
                    frame: f as i64,
                    timestamp: (f as f64 / fps) as f32,
                    vectors,
                });
            }
        }
        Lerobot {
            layout,
            fps,
            vector_keys: columns.iter().map(|(k, _)| k.to_string()).collect(),
            rows,
            listed_lengths: None,
        }
    }

    fn episodes(&self) -> Vec<i64> {
        let mut out: Vec<i64> = self.rows.iter().map(|r| r.episode).collect();
        out.dedup();
        out
    }

    /// info.json as LeRobot writes it (a video feature included, which the importer skips).
    pub fn info(&self) -> serde_json::Value {
        let mut features = serde_json::Map::new();
        for (c, key) in self.vector_keys.iter().enumerate() {
            let dim = self.rows.first().map_or(0, |r| r.vectors[c].len());
            features.insert(
                key.clone(),
                json!({"dtype": "float32", "shape": [dim], "names": null}),
            );
        }
        features.insert(
            "observation.images.top".into(),
            json!({"dtype": "video", "shape": [48, 64, 3], "names": ["height", "width", "channels"]}),
        );
        for (key, dtype) in [
            ("timestamp", "float32"),
            ("frame_index", "int64"),
            ("episode_index", "int64"),
            ("index", "int64"),
            ("task_index", "int64"),
        ] {
            features.insert(
                key.into(),
                json!({"dtype": dtype, "shape": [1], "names": null}),
            );
        }
        let (version, data_path) = match self.layout {
            Layout::V2 => (
                "v2.1",
                "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
            ),
            Layout::V3 => (
                "v3.0",
                "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
            ),
        };
        json!({
            "codebase_version": version,
            "robot_type": "test",
            "total_episodes": self.episodes().len(),
            "total_frames": self.rows.len(),
            "total_tasks": 1,
            "chunks_size": 1000,
            "fps": self.fps,
            "splits": {"train": format!("0:{}", self.episodes().len())},
            "data_path": data_path,
            "features": features,
        })
    }

    /// Writes the dataset into `dir` (created); `info` replaces the info.json of [`Lerobot::info`].
    pub fn write(&self, dir: &Path, info: Option<serde_json::Value>) {
        std::fs::create_dir_all(dir.join("meta")).unwrap();
        let info = info.unwrap_or_else(|| self.info());
        std::fs::write(
            dir.join("meta/info.json"),
            serde_json::to_string_pretty(&info).unwrap(),
        )
        .unwrap();
        let episodes = self.episodes();
        let length = |e: i64| match &self.listed_lengths {
            Some(listed) => listed[e as usize],
            None => self.rows.iter().filter(|r| r.episode == e).count() as i64,
        };
        match self.layout {
            Layout::V2 => {
                for &e in &episodes {
                    let rows: Vec<&Row> = self.rows.iter().filter(|r| r.episode == e).collect();
                    self.write_data(
                        &dir.join(format!("data/chunk-000/episode_{e:06}.parquet")),
                        &rows,
                    );
                }
                let lines: Vec<String> = episodes
                    .iter()
                    .map(|&e| {
                        json!({"episode_index": e, "tasks": ["move"], "length": length(e)})
                            .to_string()
                    })
                    .collect();
                std::fs::write(dir.join("meta/episodes.jsonl"), lines.join("\n") + "\n").unwrap();
                std::fs::write(
                    dir.join("meta/tasks.jsonl"),
                    "{\"task_index\": 0, \"task\": \"move\"}\n",
                )
                .unwrap();
            }
            Layout::V3 => {
                // Two data files: the first episode alone, then the rest.
                let (first, rest): (Vec<&Row>, Vec<&Row>) = self
                    .rows
                    .iter()
                    .partition(|r| Some(&r.episode) == episodes.first());
                self.write_data(&dir.join("data/chunk-000/file-000.parquet"), &first);
                if !rest.is_empty() {
                    self.write_data(&dir.join("data/chunk-000/file-001.parquet"), &rest);
                }
                let lengths: Vec<i64> = episodes.iter().map(|&e| length(e)).collect();
                write_int_columns(
                    &dir.join("meta/episodes/chunk-000/file-000.parquet"),
                    &[("episode_index", &episodes), ("length", &lengths)],
                );
                write_int_columns(&dir.join("meta/tasks.parquet"), &[("task_index", &[0])]);
            }
        }
    }

    fn write_data(&self, path: &Path, rows: &[&Row]) {
        let mut schema = String::from("message schema {\n");
        for key in &self.vector_keys {
            schema += &format!(
                "optional group {key} (LIST) {{ repeated group list {{ optional float element; }} }}\n"
            );
        }
        schema += "optional float timestamp;\n";
        for key in ["frame_index", "episode_index", "index", "task_index"] {
            schema += &format!("optional int64 {key};\n");
        }
        schema += "}";
        let mut writer = file_writer(path, &schema);
        let mut group = writer.next_row_group().unwrap();
        for c in 0..self.vector_keys.len() {
            let (mut values, mut def, mut rep) = (Vec::new(), Vec::new(), Vec::new());
            for row in rows {
                for (i, &v) in row.vectors[c].iter().enumerate() {
                    values.push(v);
                    def.push(3);
                    rep.push(i16::from(i > 0));
                }
            }
            let mut column = group.next_column().unwrap().unwrap();
            column
                .typed::<FloatType>()
                .write_batch(&values, Some(&def), Some(&rep))
                .unwrap();
            column.close().unwrap();
        }
        let ones = vec![1i16; rows.len()];
        let mut column = group.next_column().unwrap().unwrap();
        let ts: Vec<f32> = rows.iter().map(|r| r.timestamp).collect();
        column
            .typed::<FloatType>()
            .write_batch(&ts, Some(&ones), None)
            .unwrap();
        column.close().unwrap();
        let index: Vec<i64> = (0..rows.len() as i64).collect();
        let frames: Vec<i64> = rows.iter().map(|r| r.frame).collect();
        let episodes: Vec<i64> = rows.iter().map(|r| r.episode).collect();
        for values in [frames, episodes, index, vec![0; rows.len()]] {
            let mut column = group.next_column().unwrap().unwrap();
            column
                .typed::<Int64Type>()
                .write_batch(&values, Some(&ones), None)
                .unwrap();
            column.close().unwrap();
        }
        group.close().unwrap();
        writer.close().unwrap();
    }
}

fn file_writer(path: &Path, schema: &str) -> SerializedFileWriter<std::fs::File> {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    let schema = Arc::new(parse_message_type(schema).unwrap());
    SerializedFileWriter::new(
        std::fs::File::create(path).unwrap(),
        schema,
        Arc::new(props),
    )
    .unwrap()
}

/// A parquet file of optional int64 columns.
fn write_int_columns(path: &Path, columns: &[(&str, &[i64])]) {
    let schema = columns
        .iter()
        .fold(String::from("message schema {\n"), |s, (k, _)| {
            s + &format!("optional int64 {k};\n")
        })
        + "}";
    let mut writer = file_writer(path, &schema);
    let mut group = writer.next_row_group().unwrap();
    for (_, values) in columns {
        let ones = vec![1i16; values.len()];
        let mut column = group.next_column().unwrap().unwrap();
        column
            .typed::<Int64Type>()
            .write_batch(values, Some(&ones), None)
            .unwrap();
        column.close().unwrap();
    }
    group.close().unwrap();
    writer.close().unwrap();
}
