"""Foxglove's own message definitions, read from the protobuf schemas foxglove-sdk ships.

The console embeds Foxglove's well-known schemas (``foxglove.SceneUpdate`` ...) in their JSON form;
a test checks them against an independent source: the ``FileDescriptorSet`` that the installed
foxglove-sdk returns for the same message (``foxglove.messages.SceneUpdate.get_schema()``). This
module decodes that set with a minimal protobuf wire-format reader (only the few
``descriptor.proto`` fields needed; no protobuf package is installed) into, per message, its
fields: name, whether repeated, scalar type or the message/enum it refers to.
"""

from __future__ import annotations

import dataclasses
from typing import Iterator

# descriptor.proto FieldDescriptorProto.Type numbers -> the JSON schema type Foxglove uses.
SCALAR = {1: "number", 2: "number", 3: "integer", 4: "integer", 5: "integer", 6: "integer",
          7: "integer", 8: "boolean", 9: "string", 12: "bytes", 13: "integer", 15: "integer",
          16: "integer", 17: "integer", 18: "integer"}
TYPE_MESSAGE, TYPE_ENUM, LABEL_REPEATED = 11, 14, 3


@dataclasses.dataclass(frozen=True)
class Field:
    """One field of a message: name, repeated, and a scalar type or a referenced type name."""

    name: str
    repeated: bool
    scalar: str | None  # "number", "integer", "boolean", "string", "bytes"; None: a reference
    ref: str | None     # ".foxglove.Pose", ".google.protobuf.Timestamp", an enum's full name
    enum: bool = False


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    shift = value = 0
    while True:
        b = buf[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return value, i


def _fields(buf: bytes) -> Iterator[tuple[int, int, int | bytes]]:
    """(field number, wire type, value) of a serialized message."""
    i = 0
    while i < len(buf):
        key, i = _varint(buf, i)
        num, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(buf, i)
            yield num, wire, value
        elif wire == 2:
            n, i = _varint(buf, i)
            yield num, wire, buf[i:i + n]
            i += n
        elif wire == 1:
            yield num, wire, buf[i:i + 8]
            i += 8
        elif wire == 5:
            yield num, wire, buf[i:i + 4]
            i += 4
        else:
            raise ValueError(f"wire type {wire} not supported")


def messages(descriptor_set: bytes) -> tuple[dict[str, list[Field]], dict[str, dict[str, int]]]:
    """Messages (full name without the leading dot -> fields) and enums (full name -> value by
    name) of a serialized ``google.protobuf.FileDescriptorSet``."""
    msgs: dict[str, list[Field]] = {}
    enums: dict[str, dict[str, int]] = {}

    def enum(buf: bytes, prefix: str) -> None:
        name, values = "", {}
        for num, _, v in _fields(buf):
            if num == 1:
                name = bytes(v).decode()  # type: ignore[arg-type]
            elif num == 2:
                vname, vnum = "", 0
                for n2, _, v2 in _fields(v):  # type: ignore[arg-type]
                    if n2 == 1:
                        vname = bytes(v2).decode()  # type: ignore[arg-type]
                    elif n2 == 2:
                        vnum = int(v2)  # type: ignore[arg-type]
                values[vname] = vnum
        enums[f"{prefix}.{name}"] = values

    def message(buf: bytes, prefix: str) -> None:
        name, fields, nested = "", [], []
        for num, _, v in _fields(buf):
            if num == 1:
                name = bytes(v).decode()  # type: ignore[arg-type]
            elif num == 2:
                f = {n2: v2 for n2, _, v2 in _fields(v)}  # type: ignore[arg-type]
                ftype = int(f.get(5, 0))  # type: ignore[arg-type]
                ref = bytes(f[6]).decode().lstrip(".") if 6 in f else None  # type: ignore
                fields.append(Field(bytes(f[1]).decode(),  # type: ignore[arg-type]
                                    int(f.get(4, 1)) == LABEL_REPEATED,  # type: ignore[arg-type]
                                    SCALAR.get(ftype), ref, ftype == TYPE_ENUM))
            elif num in (3, 4):
                nested.append((num, v))
        full = f"{prefix}.{name}"
        msgs[full] = fields
        for num, v in nested:
            (message if num == 3 else enum)(v, full)  # type: ignore[arg-type]

    for num, _, file_buf in _fields(descriptor_set):
        if num != 1:
            continue
        package = ""
        parts = list(_fields(file_buf))  # type: ignore[arg-type]
        for n2, _, v2 in parts:
            if n2 == 2:
                package = bytes(v2).decode()  # type: ignore[arg-type]
        for n2, _, v2 in parts:
            if n2 == 4:
                message(v2, package)  # type: ignore[arg-type]
            elif n2 == 5:
                enum(v2, package)  # type: ignore[arg-type]
    return {k.lstrip("."): v for k, v in msgs.items()}, {k.lstrip("."): v for k, v in enums.items()}
