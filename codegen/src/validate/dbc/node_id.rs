//! Node ids carried in CAN ids. A node whose `NodeIdInCanId` attribute is set (1 to 255) puts
//! that id in the low byte of the extended id of every message it sends or receives, as the
//! DTI inverters do (`(packet << 8) | node`). The id is then declared once, on the node, and a
//! message whose id was not renumbered with it, or lost its extended flag, is refused instead
//! of silently missing the inverter.

use std::collections::{BTreeSet, HashMap};

use can_dbc::{AttributeValue, Dbc};

use super::{Builder, Frame};
use crate::diagnostic::Code;

/// The node attribute that declares the id.
const ATTRIBUTE: &str = "NodeIdInCanId";

/// Each node that declares a node id, with it (0 and values beyond a byte declare none).
pub(super) fn declared(dbc: &Dbc) -> HashMap<&str, u8> {
    dbc.attribute_values_node
        .iter()
        .filter(|a| a.name == ATTRIBUTE)
        .filter_map(|a| {
            let id = match a.value {
                AttributeValue::Uint(v) => u8::try_from(v).ok(),
                AttributeValue::Int(v) => u8::try_from(v).ok(),
                _ => None,
            }?;
            (id != 0).then_some((a.node_name.as_str(), id))
        })
        .collect()
}

impl Builder<'_, '_> {
    /// A message between a node with a declared id and nodes without one must have an
    /// extended id carrying that id in its low byte. (Between two nodes that both declare one,
    /// such as J1939 source and destination addresses, the layout is the protocol's own:
    /// nothing is checked.)
    pub(super) fn check_node_id(&mut self, frame: &Frame<'_>) {
        if self.node_ids.is_empty() {
            return;
        }
        let msg = frame.msg;
        let involved: BTreeSet<&str> = msg
            .transmitter
            .iter()
            .map(String::as_str)
            .chain(
                msg.signals
                    .iter()
                    .flat_map(|s| s.receivers.iter().map(String::as_str)),
            )
            .collect();
        let mut declaring = involved
            .into_iter()
            .filter_map(|node| self.node_ids.get(node).map(|id| (node, *id)));
        let (Some((node, node_id)), None) = (declaring.next(), declaring.next()) else {
            return;
        };
        if !frame.extended {
            self.r.report(
                Code::NodeIdNotInId,
                frame.line,
                format!(
                    "message `{}` has the standard id 0x{:X}, but node `{node}` declares \
                     {ATTRIBUTE} 0x{node_id:02X}: its messages have extended ids carrying it",
                    frame.name, frame.id
                ),
                "write the id as 0x80000000 + the 29-bit id, whose low byte is the node id",
            );
            return;
        }
        let carried = frame.id & 0xFF;
        if carried != u32::from(node_id) {
            self.r.report(
                Code::NodeIdNotInId,
                frame.line,
                format!(
                    "message `{}` (id 0x{:X}) carries node id 0x{carried:02X}, but node `{node}` \
                     declares {ATTRIBUTE} 0x{node_id:02X}",
                    frame.name, frame.id
                ),
                "renumber the message's id with the node id (its low byte), or change the node's \
                 NodeIdInCanId",
            );
        }
    }
}
