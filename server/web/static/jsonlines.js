// Where each value of a JSON text starts: "body.receivers.0.fov_deg" -> line 12. The API names a wrong field
// by such a path (the located messages of its 422 problem documents, the text the CLI prints); the submit page
// puts the message next to that line of its editor.

/** Map of dotted paths ("body", "body.room", "body.receivers.0.fov_deg") to 1-based line numbers; for an
 * object member the line of its key. Throws SyntaxError on text that is not JSON. */
export function jsonLines(text, root = "body") {
  const lines = new Map();
  let i = 0;
  let line = 1;
  const fail = (what) => {
    throw new SyntaxError(`${what} at line ${line}`);
  };
  const ws = () => {
    while (i < text.length) {
      const c = text[i];
      if (c === "\n") line += 1;
      else if (c !== " " && c !== "\t" && c !== "\r") break;
      i += 1;
    }
  };
  const string = () => {
    const start = i;
    i += 1;
    while (i < text.length && text[i] !== '"') {
      if (text[i] === "\\") i += 1;
      else if (text[i] === "\n") fail("newline in a string");
      i += 1;
    }
    if (i >= text.length) fail("unterminated string");
    i += 1;
    return JSON.parse(text.slice(start, i));
  };
  const value = (path, at) => {
    ws();
    if (!lines.has(path)) lines.set(path, at ?? line);
    const c = text[i];
    if (c === "{") {
      i += 1;
      ws();
      if (text[i] === "}") {
        i += 1;
        return;
      }
      for (;;) {
        ws();
        if (text[i] !== '"') fail("expected a key");
        const keyLine = line;
        const key = string();
        ws();
        if (text[i] !== ":") fail("expected ':'");
        i += 1;
        value(`${path}.${key}`, keyLine);
        ws();
        if (text[i] === ",") i += 1;
        else if (text[i] === "}") {
          i += 1;
          return;
        } else fail("expected ',' or '}'");
      }
    } else if (c === "[") {
      i += 1;
      ws();
      if (text[i] === "]") {
        i += 1;
        return;
      }
      for (let k = 0; ; k += 1) {
        ws();
        value(`${path}.${k}`, line);
        ws();
        if (text[i] === ",") i += 1;
        else if (text[i] === "]") {
          i += 1;
          return;
        } else fail("expected ',' or ']'");
      }
    } else if (c === '"') {
      string();
    } else {
      const m = /^-?(?:0|[1-9]\d*)(?:\.\d+)?(?:[eE][+-]?\d+)?|^true|^false|^null/.exec(text.slice(i, i + 400));
      if (!m) fail("unexpected character");
      i += m[0].length;
    }
  };
  value(root, undefined);
  ws();
  if (i < text.length) fail("text after the document");
  return lines;
}

/** The line of `loc` in a map from jsonLines: the path itself, else its longest known prefix (a missing field
 * is reported at its parent; a segment the document does not have, e.g. a union's tag, is skipped). */
export function lineOf(lines, loc) {
  const parts = String(loc).split(".");
  let path = parts[0];
  let best = lines.get(path);
  for (const part of parts.slice(1)) {
    const next = `${path}.${part}`;
    if (lines.has(next)) {
      path = next;
      best = lines.get(path);
    }
  }
  return best;
}
