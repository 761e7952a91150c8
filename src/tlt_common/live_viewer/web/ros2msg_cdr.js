// ROS 2 messages in CDR, decoded in the browser from the ros2msg schema a Foxglove server
// advertises with each channel (the type's full definition: the root type's fields, then each
// type it uses after a "MSG: package/Type" line). Any message type decodes; nothing is hard-coded.
//
// CDR as ROS 2 (Fast DDS) writes it: a 4-byte encapsulation header (byte 1: 0 big endian,
// 1 little endian), then the fields in order, each primitive aligned to its size (counted from the
// end of the header), strings as a uint32 length (with the terminating NUL) and the bytes,
// sequences as a uint32 count and the elements, fixed arrays as the elements alone.

const PRIMITIVE_SIZES = {
  bool: 1, byte: 1, char: 1, int8: 1, uint8: 1, int16: 2, uint16: 2,
  int32: 4, uint32: 4, int64: 8, uint64: 8, float32: 4, float64: 8,
};
const TEXT = new TextDecoder();

function normalName(name) {
  // "tf2_msgs/msg/TFMessage" (a channel's schema name) and "tf2_msgs/TFMessage" name one type.
  const parts = name.split("/");
  return parts.length === 3 ? `${parts[0]}/${parts[2]}` : name;
}

function parseField(line, pkg) {
  const text = line.replace(/#.*/, "").trim();
  if (!text) return null;
  const [type, name, ...rest] = text.split(/\s+/);
  if (!name || name.includes("=") || (rest[0] || "").startsWith("=")) return null; // a constant
  const m = /^([A-Za-z0-9_/]+)(?:<=\d+)?(?:\[(<=)?(\d*)\])?$/.exec(type);
  if (!m) throw new Error(`cannot parse the field "${line}"`);
  const [, base, bounded, length] = m;
  const isArray = type.includes("[");
  const field = {
    name,
    base,
    isArray,
    fixedLength: isArray && !bounded && length !== "" ? Number(length) : null,
  };
  if (base === "wstring") throw new Error(`${name}: wstring fields are not decoded here`);
  if (!(base in PRIMITIVE_SIZES) && base !== "string") {
    field.complex = base.includes("/") ? normalName(base) : base === "Header" ? "std_msgs/Header" : `${pkg}/${base}`;
  }
  return field;
}

// The types of one schema: {root: "pkg/Type", types: Map("pkg/Type" -> fields)}.
export function parseSchema(schemaName, schemaText) {
  const root = normalName(schemaName);
  const types = new Map();
  const sections = schemaText.split(/^=+\s*$/m);
  sections.forEach((section, i) => {
    const lines = section.split("\n");
    let name = root;
    if (i > 0) {
      const header = lines.findIndex((l) => l.startsWith("MSG:"));
      if (header < 0) return;
      name = normalName(lines[header].slice(4).trim());
      lines.splice(0, header + 1);
    }
    const pkg = name.split("/")[0];
    types.set(name, lines.map((l) => parseField(l, pkg)).filter(Boolean));
  });
  for (const fields of types.values()) {
    for (const f of fields) {
      if (f.complex && !types.has(f.complex)) {
        // A type named without its package that is not in the schema's package: find it by name.
        const short = f.complex.split("/")[1];
        const found = [...types.keys()].find((k) => k.endsWith(`/${short}`));
        if (!found) throw new Error(`${name}: the schema does not define ${f.complex}`);
        f.complex = found;
      }
    }
  }
  return { root, types };
}

class Reader {
  constructor(bytes) {
    this.bytes = bytes;
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    if (bytes.byteLength < 4) throw new Error("a CDR message shorter than its header");
    this.little = (bytes[1] & 1) === 1;
    this.offset = 4;
  }

  align(size) {
    const rem = (this.offset - 4) % size;
    if (rem) this.offset += size - rem;
  }

  primitive(type) {
    const size = PRIMITIVE_SIZES[type];
    this.align(size);
    const v = this.view;
    const o = this.offset;
    this.offset += size;
    switch (type) {
      case "bool": return v.getUint8(o) !== 0;
      case "byte": case "char": case "uint8": return v.getUint8(o);
      case "int8": return v.getInt8(o);
      case "int16": return v.getInt16(o, this.little);
      case "uint16": return v.getUint16(o, this.little);
      case "int32": return v.getInt32(o, this.little);
      case "uint32": return v.getUint32(o, this.little);
      case "int64": return Number(v.getBigInt64(o, this.little));
      case "uint64": return Number(v.getBigUint64(o, this.little));
      case "float32": return v.getFloat32(o, this.little);
      case "float64": return v.getFloat64(o, this.little);
      default: throw new Error(`not a primitive: ${type}`);
    }
  }

  string() {
    const length = this.primitive("uint32");
    const start = this.offset;
    this.offset += length;
    return TEXT.decode(this.bytes.subarray(start, start + Math.max(0, length - 1)));
  }
}

function readValue(reader, field, types) {
  if (field.complex) return readMessage(reader, types.get(field.complex), types);
  if (field.base === "string") return reader.string();
  return reader.primitive(field.base);
}

function readField(reader, field, types) {
  if (!field.isArray) return readValue(reader, field, types);
  const count = field.fixedLength ?? reader.primitive("uint32");
  if (field.base === "uint8" || field.base === "byte" || field.base === "char") {
    const start = reader.offset;
    reader.offset += count;
    return reader.bytes.slice(start, start + count);
  }
  const out = new Array(count);
  for (let i = 0; i < count; i++) out[i] = readValue(reader, field, types);
  return out;
}

function readMessage(reader, fields, types) {
  const out = {};
  for (const field of fields) out[field.name] = readField(reader, field, types);
  return out;
}

// A decoder for one channel: bytes (a Uint8Array of CDR) -> a plain object of the message.
export function cdrDecoder(schemaName, schemaText) {
  const { root, types } = parseSchema(schemaName, schemaText);
  const fields = types.get(root);
  return (bytes) => readMessage(new Reader(bytes), fields, types);
}
