// Validates Kubernetes manifests offline (deploy/check.sh): every YAML document must parse, name
// a known apiVersion and kind, pass that kind's JSON schema (kubernetes-models, generated from
// the Kubernetes OpenAPI specification: types, required fields, enums, formats), and hold no
// field the API does not define (a typo or a wrong indentation, which the API server's strict
// field validation rejects; the schemas alone let unknown fields through, so the field names are
// checked against the models' type declarations). Kustomize files are skipped here: kubectl
// kustomize checks them by rendering.
//
// With --policy secure|dev-insecure, the documents (one kustomization's rendered output, or the
// files of deploy/k8s/base) are also checked against the security rules of docs/deploy.md
// ("Secure defaults"): every container running `evloc-localizer serve` on a non-loopback address
// has TLS (--tls-cert, --tls-key) and authentication (--auth-tokens or --tls-client-ca) and no
// --insecure (secure), or says --insecure explicitly (dev-insecure, the overlay of that name
// only); a NetworkPolicy selects its pods, limits ingress to named ports and denies egress; and
// metrics on a non-loopback address are only on a port that policy restricts.
//
// Usage: node validate-k8s.mjs [--policy secure|dev-insecure] FILE...
//   ("-" reads standard input, e.g. kubectl kustomize output)
// Exit status: 0 all valid, 1 invalid documents or policy violations (each on stderr), 2 bad
// usage.
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";
import YAML from "yaml";

const here = path.dirname(fileURLToPath(import.meta.url));
const modules = path.join(here, "node_modules");

// Packages holding the models of an API group (the core group is "v1" in kubernetes-models).
function modelModule(apiVersion) {
  if (apiVersion.startsWith("monitoring.coreos.com/")) {
    return `@kubernetes-models/prometheus-operator/${apiVersion}`;
  }
  return `kubernetes-models/${apiVersion}`;
}

// ---- Field names from the models' TypeScript declarations ------------------------------------

const ANY = { kind: "any" };
const declarations = new Map();  // file -> { imports, interfaces, aliases }

function tokenize(text) {
  const tokens = [];
  const pattern = /\s+|\/\*[\s\S]*?\*\/|\/\/[^\n]*|"(?:[^"\\]|\\.)*"|'(?:[^'\\]|\\.)*'|[A-Za-z_$][\w$]*|\d+|\S/g;
  for (const match of text.matchAll(pattern)) {
    const token = match[0];
    if (/^\s/.test(token) || token.startsWith("/*") || token.startsWith("//")) continue;
    tokens.push(token);
  }
  return tokens;
}

// A parser for the subset of TypeScript types that the model declarations use.
class TypeParser {
  constructor(tokens, file, imports) {
    this.tokens = tokens;
    this.index = 0;
    this.file = file;
    this.imports = imports;
  }
  peek() { return this.tokens[this.index]; }
  next() { return this.tokens[this.index++]; }
  expect(token) {
    const got = this.next();
    if (got !== token) throw new Error(`${this.file}: expected '${token}', got '${got}'`);
  }
  parseType() {
    if (this.peek() === "|") this.next();
    let type = this.parsePrimary();
    let union = false;
    while (this.peek() === "|") {
      this.next();
      this.parsePrimary();
      union = true;
    }
    return union ? ANY : type;
  }
  parsePrimary() {
    const token = this.next();
    let type = ANY;
    if (token === "{") {
      type = this.parseObjectBody();
    } else if (token === "(") {
      type = this.parseType();
      this.expect(")");
    } else if (token === "Array" && this.peek() === "<") {
      this.next();
      type = { kind: "array", element: this.parseType() };
      this.expect(">");
    } else if (/^[A-Za-z_$]/.test(token)) {
      if (this.peek() === "<") this.skipGenericArguments();
      else if (this.imports.has(token)) type = { kind: "ref", name: token, file: this.imports.get(token) };
    }
    while (this.peek() === "[" && this.tokens[this.index + 1] === "]") {
      this.index += 2;
      type = { kind: "array", element: type };
    }
    return type;
  }
  skipGenericArguments() {
    let depth = 0;
    do {
      const token = this.next();
      if (token === "<") depth++;
      if (token === ">") depth--;
    } while (depth > 0);
  }
  // After "{": properties, or an index signature (a map).
  parseObjectBody() {
    const properties = new Map();
    let map = null;
    while (this.peek() !== "}") {
      if (this.peek() === "[") {
        this.next();
        this.next();  // key name
        this.expect(":");
        this.parseType();
        this.expect("]");
        this.expect(":");
        map = this.parseType();
      } else {
        let name = this.next();
        if (name.startsWith('"') || name.startsWith("'")) name = name.slice(1, -1);
        if (this.peek() === "?") this.next();
        if (this.peek() === "(") {  // a method: not data
          this.skipUntilSeparator();
          continue;
        }
        this.expect(":");
        properties.set(name, this.parseType());
      }
      if (this.peek() === ";" || this.peek() === ",") this.next();
    }
    this.next();
    if (map) return { kind: "map", value: map };
    return { kind: "object", properties };
  }
  skipUntilSeparator() {
    let depth = 0;
    for (;;) {
      const token = this.next();
      if (token === "(" || token === "{" || token === "<") depth++;
      if (token === ")" || token === "}" || token === ">") depth--;
      if (depth === 0 && (token === ";" || token === ",")) return;
    }
  }
}

function resolveImport(fromFile, specifier) {
  if (specifier.startsWith(".")) {
    return path.resolve(path.dirname(fromFile), specifier.replace(/\.js$/, "") + ".d.ts");
  }
  return path.join(modules, specifier + ".d.ts");
}

function loadDeclarations(file) {
  if (declarations.has(file)) return declarations.get(file);
  const entry = { imports: new Map(), interfaces: new Map(), aliases: new Map() };
  declarations.set(file, entry);
  if (!fs.existsSync(file)) return entry;
  const text = fs.readFileSync(file, "utf8");
  for (const match of text.matchAll(/import\s*\{([^}]*)\}\s*from\s*"([^"]+)"/g)) {
    for (const name of match[1].split(",").map((s) => s.trim()).filter(Boolean)) {
      entry.imports.set(name.split(/\s+as\s+/).pop(), resolveImport(file, match[2]));
    }
  }
  for (const match of text.matchAll(/export\s+type\s*\{([^}]*)\}/g)) {
    for (const item of match[1].split(",")) {
      const [local, alias] = item.split(/\s+as\s+/).map((s) => s.trim());
      if (alias) entry.aliases.set(alias, local);
    }
  }
  const tokens = tokenize(text);
  for (let i = 0; i < tokens.length; i++) {
    if (tokens[i] === "export" && tokens[i + 1] === "interface") {
      const name = tokens[i + 2];
      let j = i + 3;
      const bases = [];
      if (tokens[j] === "extends") {
        j++;
        while (tokens[j] !== "{") {
          if (tokens[j] !== ",") bases.push(tokens[j]);
          j++;
        }
      }
      const parser = new TypeParser(tokens, file, entry.imports);
      parser.index = j + 1;
      const type = parser.parseObjectBody();
      // TypeMeta only declares apiVersion and kind, which the interfaces repeat.
      type.bases = bases.filter((base) => base !== "TypeMeta");
      entry.interfaces.set(name, type);
      i = parser.index - 1;
    }
  }
  return entry;
}

function resolveRef(type) {
  const entry = loadDeclarations(type.file);
  const local = entry.aliases.get(type.name) ?? type.name;
  return entry.interfaces.get(local) ?? ANY;  // a type alias (Quantity, IntOrString, ...): a scalar
}

function checkFields(value, type, where, errors) {
  if (value === null || value === undefined) return;
  if (type.kind === "ref") {
    checkFields(value, resolveRef(type), where, errors);
  } else if (type.kind === "array") {
    if (Array.isArray(value)) value.forEach((item, i) => checkFields(item, type.element, `${where}[${i}]`, errors));
  } else if (type.kind === "map") {
    if (typeof value === "object" && !Array.isArray(value)) {
      for (const [key, item] of Object.entries(value)) checkFields(item, type.value, `${where}.${key}`, errors);
    }
  } else if (type.kind === "object") {
    if (typeof value !== "object" || Array.isArray(value)) return;  // the schema reports the type
    if (type.bases && type.bases.length > 0) return;  // not flattened: only the schema check
    for (const [key, item] of Object.entries(value)) {
      if (!type.properties.has(key)) {
        errors.push(`${where}.${key}: unknown field (known: ${[...type.properties.keys()].join(", ")})`);
      } else {
        checkFields(item, type.properties.get(key), `${where}.${key}`, errors);
      }
    }
  }
}

// ---- Documents ------------------------------------------------------------------------------

async function validateDocument(object, source) {
  if (object === null || object === undefined) return [];  // an empty document
  if (typeof object !== "object" || Array.isArray(object)) return [`${source}: not a mapping`];
  const { apiVersion, kind } = object;
  if (typeof apiVersion !== "string" || typeof kind !== "string") {
    return [`${source}: apiVersion and kind are required`];
  }
  if (apiVersion.startsWith("kustomize.config.k8s.io/")) return null;
  const name = `${kind} ${object.metadata?.name ?? "(no name)"}`;
  let models;
  try {
    models = await import(modelModule(apiVersion));
  } catch {
    return [`${source}: ${name}: unknown apiVersion '${apiVersion}'`];
  }
  const Model = models[kind];
  if (typeof Model !== "function") return [`${source}: ${name}: unknown kind '${kind}' in ${apiVersion}`];
  const errors = [];
  try {
    new Model(object).validate();
  } catch (error) {
    errors.push(`${source}: ${name}: ${error.message}`);
  }
  const file = path.join(modules, modelModule(apiVersion), `${kind}.d.ts`);
  const entry = loadDeclarations(file);
  const type = entry.interfaces.get(`I${kind}`);
  if (!type) {
    errors.push(`${source}: ${name}: no type declaration for ${kind} (${file})`);
  } else {
    const fieldErrors = [];
    checkFields(object, type, kind, fieldErrors);
    for (const error of fieldErrors) errors.push(`${source}: ${name}: ${error}`);
  }
  return errors;
}

// ---- Security policy ------------------------------------------------------------------------

// True for a listen address that only this machine reaches (as IsLoopbackListenAddress in
// localizer/service/auth.cc, for the forms a manifest uses).
function isLoopback(address) {
  const host = address.replace(/^ipv[46]:/, "").replace(/:[^:]*$/, "").replace(/^\[(.*)\]$/, "$1");
  return address.startsWith("unix:") || host === "localhost" || host === "::1" || /^127\./.test(host);
}

// The value of each `--flag value` in args (flags without a value map to true).
function flagsOf(args) {
  const flags = new Map();
  for (let i = 0; i < args.length; i++) {
    const arg = String(args[i]);
    if (!arg.startsWith("--")) continue;
    const value = args[i + 1];
    if (value === undefined || String(value).startsWith("--")) {
      flags.set(arg, true);
    } else {
      flags.set(arg, String(value));
      i++;
    }
  }
  return flags;
}

// True when every label of `selector` (a matchLabels map) is on `labels`.
function selects(selector, labels) {
  return Object.entries(selector ?? {}).every(([key, value]) => labels?.[key] === value);
}

function checkPolicy(objects, policy) {
  const errors = [];
  const policies = objects.filter((o) => o?.kind === "NetworkPolicy");
  let servers = 0;
  for (const object of objects) {
    const template = object?.spec?.template;
    if (!template?.spec?.containers) continue;
    const name = `${object.kind} ${object.metadata?.name}`;
    const labels = template.metadata?.labels ?? {};
    for (const container of template.spec.containers) {
      const args = (container.args ?? []).map(String);
      if (args[0] !== "serve" || !String(container.image ?? "").includes("evloc-localizer")) continue;
      servers++;
      const where = `${name}, container ${container.name}`;
      const flags = flagsOf(args);
      const listen = flags.get("--listen") ?? "127.0.0.1:50051";
      const tls = flags.has("--tls-cert") && flags.has("--tls-key");
      const auth = flags.has("--auth-tokens") || flags.has("--tls-client-ca");
      const insecure = flags.has("--insecure");
      if (policy === "secure") {
        if (insecure) errors.push(`${where}: --insecure outside overlays/dev-insecure`);
        if (!isLoopback(listen) && !tls) errors.push(`${where}: listens on ${listen} without TLS (--tls-cert, --tls-key)`);
        if (!isLoopback(listen) && !auth) errors.push(`${where}: listens on ${listen} without --auth-tokens or --tls-client-ca`);
        for (const probe of ["startupProbe", "readinessProbe", "livenessProbe"]) {
          if (tls && container[probe]?.grpc) {
            errors.push(`${where}: ${probe} is a native gRPC probe (plaintext only) on a TLS server`);
          }
        }
      } else if (!insecure && !(tls && auth)) {
        errors.push(`${where}: a plaintext server must say --insecure explicitly`);
      }
      // Readiness asks whether the replica admits sessions (service evloc.api.Localizer), so a
      // full replica leaves the Service; liveness asks for the overall health (a full replica is
      // alive; restarting it would drop its sessions).
      const probeService = (probe) => {
        if (!probe) return null;
        if (probe.grpc) return probe.grpc.service ?? "";
        const command = (probe.exec?.command ?? []).map(String);
        if (!command.includes("--health-check")) return null;
        return flagsOf(command).get("--health-service") ?? "";
      };
      const readiness = probeService(container.readinessProbe);
      if (readiness !== "evloc.api.Localizer") {
        errors.push(`${where}: readinessProbe must ask for the health of service evloc.api.Localizer (got ${JSON.stringify(readiness)})`);
      }
      const liveness = probeService(container.livenessProbe);
      if (liveness !== "") {
        errors.push(`${where}: livenessProbe must ask for the overall health (service "", got ${JSON.stringify(liveness)})`);
      }
      const matching = policies.filter((p) => selects(p.spec?.podSelector?.matchLabels, labels));
      if (matching.length === 0) {
        errors.push(`${where}: no NetworkPolicy selects its pods (labels ${JSON.stringify(labels)})`);
        continue;
      }
      const ingressPorts = new Set();
      let openIngress = false;
      let egressDenied = false;
      for (const networkPolicy of matching) {
        const types = networkPolicy.spec?.policyTypes ?? [];
        if (types.includes("Egress") && (networkPolicy.spec?.egress ?? []).length === 0) egressDenied = true;
        if (!types.includes("Ingress")) continue;
        for (const rule of networkPolicy.spec?.ingress ?? []) {
          if (!rule.ports || rule.ports.length === 0 || !rule.from || rule.from.length === 0) openIngress = true;
          for (const port of rule.ports ?? []) ingressPorts.add(String(port.port));
        }
      }
      if (openIngress) errors.push(`${where}: a NetworkPolicy ingress rule without 'from' or 'ports' lets everything in`);
      if (!egressDenied) errors.push(`${where}: no NetworkPolicy denies its egress (it opens no connection)`);
      const metrics = flags.get("--metrics");
      if (typeof metrics === "string" && metrics.includes(":") && !isLoopback(metrics)) {
        const port = metrics.replace(/^.*:/, "");
        const named = (container.ports ?? []).find((p) => String(p.containerPort) === port)?.name;
        if (!ingressPorts.has(port) && !(named && ingressPorts.has(named))) {
          errors.push(`${where}: metrics on ${metrics} but no NetworkPolicy ingress rule restricts port ${port}`);
        }
      }
    }
  }
  return { errors, servers };
}

async function main(argv) {
  let policy = null;
  const files = [...argv];
  if (files[0] === "--policy") {
    policy = files[1];
    files.splice(0, 2);
    if (policy !== "secure" && policy !== "dev-insecure") {
      console.error(`validate-k8s: --policy expects secure or dev-insecure, got '${policy}'`);
      return 2;
    }
  }
  if (files.length === 0) {
    console.error("usage: node validate-k8s.mjs [--policy secure|dev-insecure] FILE... ('-' for standard input)");
    return 2;
  }
  const objects = [];
  let failures = 0;
  let checked = 0;
  for (const file of files) {
    const text = file === "-" ? fs.readFileSync(0, "utf8") : fs.readFileSync(file, "utf8");
    const source = file === "-" ? "<stdin>" : file;
    const documents = YAML.parseAllDocuments(text);
    for (const [i, document] of documents.entries()) {
      const where = documents.length > 1 ? `${source} (document ${i + 1})` : source;
      if (document.errors.length > 0) {
        for (const error of document.errors) console.error(`${where}: YAML: ${error.message}`);
        failures++;
        continue;
      }
      objects.push(document.toJS());
      const errors = await validateDocument(document.toJS(), where);
      if (errors === null) continue;
      checked++;
      for (const error of errors) console.error(error);
      if (errors.length > 0) failures++;
    }
  }
  console.log(`validate-k8s: ${checked} objects checked, ${failures} invalid`);
  if (policy) {
    const { errors, servers } = checkPolicy(objects, policy);
    for (const error of errors) console.error(`policy ${policy}: ${error}`);
    console.log(`validate-k8s: policy ${policy}: ${servers} localizer containers, ${errors.length} violations`);
    if (errors.length > 0) failures++;
  }
  return failures > 0 ? 1 : 0;
}

process.exitCode = await main(process.argv.slice(2));
