//! Safetensors files with reproducible bytes. The `safetensors` crate takes the metadata as a
//! `HashMap`, whose iteration order changes from process to process, so the same dataset written
//! twice had different bytes and a different digest in every checkpoint trained on it. Here the
//! header is written again with its keys sorted (serde_json's map is ordered) and padded to 8
//! bytes as the format requires; tensor offsets are relative to the data section and unchanged.
use anyhow::{bail, Context};
use safetensors::tensor::View;
use std::collections::{BTreeMap, HashMap};

/// `safetensors::serialize`, with the header's keys (tensor names and metadata) in sorted order.
pub fn serialize<S, V, I>(
    tensors: I,
    metadata: &BTreeMap<String, String>,
) -> anyhow::Result<Vec<u8>>
where
    S: AsRef<str> + Ord + std::fmt::Display,
    V: View,
    I: IntoIterator<Item = (S, V)>,
{
    let meta: HashMap<String, String> = metadata.clone().into_iter().collect();
    let bytes = safetensors::serialize(tensors, Some(meta)).context("serializing safetensors")?;
    sort_header(&bytes)
}

/// Re-emits the JSON header of safetensors `bytes` with sorted keys; the data is copied as is.
fn sort_header(bytes: &[u8]) -> anyhow::Result<Vec<u8>> {
    let Some(head) = bytes.get(..8) else {
        bail!("safetensors bytes shorter than the 8-byte header length")
    };
    let len = u64::from_le_bytes(head.try_into()?);
    let end = usize::try_from(len)
        .ok()
        .and_then(|n| n.checked_add(8))
        .filter(|&e| e <= bytes.len());
    let Some(end) = end else {
        bail!(
            "safetensors header length {len} exceeds the {} bytes",
            bytes.len()
        )
    };
    let header: serde_json::Value =
        serde_json::from_slice(&bytes[8..end]).context("safetensors header")?;
    let mut json = serde_json::to_vec(&header)?;
    json.resize(json.len().next_multiple_of(8), b' ');
    let mut out = Vec::with_capacity(8 + json.len() + bytes.len() - end);
    out.extend_from_slice(&(json.len() as u64).to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&bytes[end..]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use safetensors::tensor::{Dtype, SafeTensors, TensorView};

    fn write(meta: &BTreeMap<String, String>) -> Vec<u8> {
        let a: Vec<u8> = [1.0f32, -2.0, 3.5]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let b: Vec<u8> = [7i64].iter().flat_map(|v| v.to_le_bytes()).collect();
        let views = [
            ("zeta", TensorView::new(Dtype::F32, vec![3], &a).unwrap()),
            ("alpha", TensorView::new(Dtype::I64, vec![1], &b).unwrap()),
        ];
        serialize(views, meta).unwrap()
    }

    #[test]
    fn same_content_gives_the_same_bytes_and_reads_back() {
        let meta: BTreeMap<String, String> = [
            ("task", "push"),
            ("dt", "0.1"),
            ("source", "scripted expert, seeds 0..100"),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
        // Each call builds a new HashMap with its own random order; the bytes must not depend on it.
        let first = write(&meta);
        for _ in 0..20 {
            assert_eq!(write(&meta), first);
        }
        let header_len = u64::from_le_bytes(first[..8].try_into().unwrap()) as usize;
        assert_eq!(header_len % 8, 0);
        let header = std::str::from_utf8(&first[8..8 + header_len]).unwrap();
        let (dt, source, task) = (
            header.find("\"dt\"").unwrap(),
            header.find("\"source\"").unwrap(),
            header.find("\"task\"").unwrap(),
        );
        assert!(
            dt < source && source < task,
            "metadata keys not sorted: {header}"
        );

        let (_, read_meta) = SafeTensors::read_metadata(&first).unwrap();
        assert_eq!(
            read_meta
                .metadata()
                .as_ref()
                .unwrap()
                .get("task")
                .map(String::as_str),
            Some("push")
        );
        let st = SafeTensors::deserialize(&first).unwrap();
        let zeta = st.tensor("zeta").unwrap();
        assert_eq!(zeta.shape(), &[3]);
        assert_eq!(
            f32::from_le_bytes(zeta.data()[4..8].try_into().unwrap()),
            -2.0
        );
        assert_eq!(
            i64::from_le_bytes(st.tensor("alpha").unwrap().data().try_into().unwrap()),
            7
        );
    }

    #[test]
    fn truncated_bytes_are_an_error() {
        assert!(sort_header(&[1, 2, 3]).is_err());
        assert!(sort_header(&[200, 0, 0, 0, 0, 0, 0, 0, b'{', b'}']).is_err());
    }
}
