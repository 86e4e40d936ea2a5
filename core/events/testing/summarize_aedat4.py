#!/usr/bin/python3
"""Summarizes an AEDAT 4.0 file independently of evloc's reader, for the tests on real recordings
(core/events/aedat4_test.cc): the IOHeader and the packet framing are read with `struct`, the
tables with Debian's python3-flatbuffers (its generic Table accessors, fed the field numbers of
DV's schemas by hand), the bodies decompressed with python3-lz4 and python3-zstandard
(docs.inivation.com, "AEDAT 4.0"; docs/event-formats.md, section 8).

Usage: summarize_aedat4.py FILE.aedat4 [OUT.txt]

Writes one line per stream and per stream type, in the stream ids' order:
  stream ID TYPE packets N
  events ID count N on N outside N t_first_us T t_last_us T sum_dt_us S sum_x S sum_y S
  imu ID count N t_first_us T t_last_us T
  triggers ID count N
where the event sums are over the events inside the stream's sizeX x sizeY (those a reader
keeps), `outside` counts the others, and sum_dt_us is the sum of (t - t_first_us).
"""

import re
import struct
import sys

import flatbuffers
import lz4.frame
import zstandard

MAGIC = b"#!AER-DAT4.0\r\n"


def table_at(buf, offset):
    """The root table of the flatbuffer at buf[offset:] (not size-prefixed)."""
    root = struct.unpack_from("<I", buf, offset)[0]
    return flatbuffers.table.Table(buf, offset + root)


def field_offset(table, slot):
    return table.Offset(4 + 2 * slot)


def scalar(table, slot, kind, default):
    o = field_offset(table, slot)
    return table.Get(kind, o + table.Pos) if o else default


def vector(table, slot):
    """(start, length) of the vector in `slot`, or (0, 0)."""
    o = field_offset(table, slot)
    if not o:
        return 0, 0
    return table.Vector(o), table.VectorLen(o)


def decompress(data, compression):
    if compression == 0:
        return data
    if compression in (1, 2):
        return lz4.frame.decompress(data)
    if compression in (3, 4):
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=1 << 28)
    raise ValueError("unknown compression %d" % compression)


def streams_of(info):
    """{id: (type, sizeX or None, sizeY or None)} from the infoNode XML."""
    streams = {}
    for match in re.finditer(r'<node name="(\d+)" path="[^"]*outInfo/\d+/">(.*?)\n        </node>',
                             info, re.S):
        body = match.group(2)
        type_id = re.search(r'key="typeIdentifier" type="string">(\w+)<', body).group(1)
        size_x = re.search(r'key="sizeX" type="int">(\d+)<', body)
        size_y = re.search(r'key="sizeY" type="int">(\d+)<', body)
        streams[int(match.group(1))] = (type_id, int(size_x.group(1)) if size_x else None,
                                        int(size_y.group(1)) if size_y else None)
    return streams


def summarize(path):
    data = open(path, "rb").read()
    if not data.startswith(MAGIC):
        raise ValueError("%s: not an AEDAT 4.0 file" % path)
    offset = len(MAGIC)
    header_size = struct.unpack_from("<I", data, offset)[0]
    header = table_at(data, offset + 4)
    compression = scalar(header, 0, flatbuffers.number_types.Int32Flags, 0)
    table_position = scalar(header, 1, flatbuffers.number_types.Int64Flags, -1)
    info = header.String(field_offset(header, 2) + header.Pos).decode()
    streams = streams_of(info)
    offset += 4 + header_size
    end = table_position if table_position >= 0 else len(data)

    packets = {i: 0 for i in streams}
    events = {}
    imu = {}
    triggers = {}
    while offset + 8 <= end:
        stream_id, size = struct.unpack_from("<iI", data, offset)
        body = decompress(data[offset + 8 : offset + 8 + size], compression)
        offset += 8 + size
        packets[stream_id] += 1
        type_id, size_x, size_y = streams[stream_id]
        root = table_at(body, 4)  # after the size prefix
        start, length = vector(root, 0) if type_id in ("EVTS", "IMUS", "TRIG") else (0, 0)
        if type_id == "EVTS":
            e = events.setdefault(stream_id, dict(count=0, on=0, outside=0, t=[], x=0, y=0))
            for i in range(length):
                t, x, y, on = struct.unpack_from("<qhh?", body, start + 16 * i)
                if not (0 <= x < size_x and 0 <= y < size_y):
                    e["outside"] += 1
                    continue
                e["count"] += 1
                e["on"] += int(on)
                e["t"].append(t)
                e["x"] += x
                e["y"] += y
        elif type_id == "IMUS":
            s = imu.setdefault(stream_id, [])
            for i in range(length):
                position = start + 4 * i + struct.unpack_from("<I", body, start + 4 * i)[0]
                element = flatbuffers.table.Table(body, position)
                s.append(scalar(element, 0, flatbuffers.number_types.Int64Flags, 0))
        elif type_id == "TRIG":
            triggers[stream_id] = triggers.get(stream_id, 0) + length

    lines = []
    for stream_id in sorted(streams):
        lines.append("stream %d %s packets %d" % (stream_id, streams[stream_id][0],
                                                  packets[stream_id]))
    for stream_id, e in sorted(events.items()):
        t = e["t"]
        lines.append("events %d count %d on %d outside %d t_first_us %d t_last_us %d sum_dt_us %d "
                     "sum_x %d sum_y %d" % (stream_id, e["count"], e["on"], e["outside"], t[0],
                                            t[-1], sum(v - t[0] for v in t), e["x"], e["y"]))
    for stream_id, times in sorted(imu.items()):
        lines.append("imu %d count %d t_first_us %d t_last_us %d" % (stream_id, len(times),
                                                                    times[0], times[-1]))
    for stream_id, count in sorted(triggers.items()):
        lines.append("triggers %d count %d" % (stream_id, count))
    return "\n".join(lines) + "\n"


def main(argv):
    if len(argv) not in (2, 3):
        sys.stderr.write(__doc__)
        return 2
    text = summarize(argv[1])
    if len(argv) == 3:
        with open(argv[2], "w") as out:
            out.write(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
