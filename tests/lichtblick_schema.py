"""Lichtblick's JSON-schema rules in Python, so a test can tell whether Lichtblick opens a channel.

Lichtblick (and Foxglove Studio before it) turns a ``jsonschema`` channel's schema into message
datatypes with ``parseJsonSchema`` (Lichtblick-Suite/lichtblick,
``packages/mcap-support/src/parseJsonSchema.ts``, read at commit 660985ee); a schema it cannot
parse leaves the channel unusable in every panel ("Unsupported type ... for ..."). This module
ports that function's rules faithfully (a port of the rules, not of its code), without the
postprocessing it also builds:

* every schema it recurses into must have ``"type": "object"`` and a ``properties`` object
  (``Object.entries(schema.properties)`` on a missing one throws);
* a property with ``oneOf`` is allowed only when every alternative has a numeric ``const`` (an
  enum), and is then a ``uint32``;
* a property's ``type`` must be one string of ``boolean``, ``string`` (no ``contentEncoding``
  or ``base64``), ``number``/``integer``, ``object`` (recursed into) or ``array``; a list of
  types (a union such as ``["number", "null"]``), ``null``, or no type at all is refused;
* an array's ``items`` must have a ``type`` of ``boolean``, ``string`` (no
  ``contentEncoding``), ``number``/``integer`` or ``object`` (recursed into); arrays of arrays,
  unions and untyped items are refused.
"""

from __future__ import annotations

from typing import Any

SOURCE = ("Lichtblick-Suite/lichtblick packages/mcap-support/src/parseJsonSchema.ts "
          "(commit 660985ee7fb002530647a8dfe763d89964d9cb11)")


class Unsupported(ValueError):
    """Lichtblick's parser would throw on this schema (the message says where and why)."""


def parse_json_schema(schema: dict[str, Any], root: str) -> dict[str, list[dict[str, Any]]]:
    """The datatypes Lichtblick derives from ``schema`` (type name -> field definitions).

    Raises:
        Unsupported: where Lichtblick's ``parseJsonSchema`` throws, with the same wording.
    """
    datatypes: dict[str, list[dict[str, Any]]] = {}

    def fields_of(node: Any, type_name: str, key_path: list[str]) -> None:
        if not isinstance(node, dict) or node.get("type") != "object":
            got = node.get("type") if isinstance(node, dict) else node
            raise Unsupported(f'Expected "type": "object" for schema {type_name}, got {got!r}')
        props = node.get("properties")
        if not isinstance(props, dict):  # Object.entries(undefined) throws a TypeError
            raise Unsupported(f"schema {type_name} has no properties")
        fields: list[dict[str, Any]] = []
        for name, field in props.items():
            where = ".".join(key_path + [name])
            if not isinstance(field, dict):
                raise Unsupported(f"Unsupported type for {where}: not a schema")
            if isinstance(field.get("oneOf"), list):
                alternatives = field["oneOf"]
                if all(isinstance(a, dict) and isinstance(a.get("const"), (int, float))
                       and not isinstance(a.get("const"), bool) for a in alternatives):
                    fields += [{"name": a.get("title"), "type": "uint32", "isConstant": True,
                                "value": a["const"]} for a in alternatives]
                    fields.append({"name": name, "type": "uint32"})
                    continue
                raise Unsupported(f"Unsupported type for {where}: oneOf alternatives must have "
                                  "number values")
            kind = field.get("type")
            if kind == "boolean":
                fields.append({"name": name, "type": "bool"})
            elif kind == "string":
                encoding = field.get("contentEncoding")
                if encoding is None:
                    fields.append({"name": name, "type": "string"})
                elif encoding == "base64":
                    fields.append({"name": name, "type": "uint8", "isArray": True})
                else:
                    raise Unsupported(f"Unsupported contentEncoding {encoding!r} in {where}")
            elif kind in ("number", "integer"):
                fields.append({"name": name, "type": "float64"})
            elif kind == "object":
                nested = f"{type_name}.{name}"
                fields_of(field, nested, key_path + [name])
                fields.append({"name": name, "type": nested, "isComplex": True})
            elif kind == "array":
                items = field.get("items")
                item_kind = items.get("type") if isinstance(items, dict) else None
                if item_kind == "boolean":
                    fields.append({"name": name, "type": "bool", "isArray": True})
                elif item_kind == "string":
                    if items.get("contentEncoding") is not None:
                        raise Unsupported(f"Unsupported contentEncoding "
                                          f"{items['contentEncoding']!r} for array item {where}")
                    fields.append({"name": name, "type": "string", "isArray": True})
                elif item_kind in ("number", "integer"):
                    fields.append({"name": name, "type": "float64", "isArray": True})
                elif item_kind == "object":
                    nested = f"{type_name}.{name}"
                    fields_of(items, nested, key_path + [name])
                    fields.append({"name": name, "type": nested, "isComplex": True,
                                   "isArray": True})
                else:
                    raise Unsupported(f"Unsupported type {item_kind!r} for array item {where}")
            else:  # "null", a list of types (a union), or none
                raise Unsupported(f"Unsupported type {kind!r} for {where}")
        datatypes[type_name] = fields

    fields_of(schema, root, [])
    return datatypes
