// The documentation's promises, checked against the repository and the programs (ctest docs.LinksAndOptions):
//   1. every relative link and image in README.md and docs/*.md exists, and a link's #anchor is a heading there;
//   2. every repository path the docs name in code (deploy/..., tests/..., idl/...) exists;
//   3. every facescan program the docs run exists, and every --option the docs give a program (or a facescan /
//      facescan-bench command) is in that program's --help; an option named on its own is in some program's.
// Usage: node docs_check.mjs SOURCE_DIR PROGRAM=PATH...   (facescan, facescan-agent, facescan-server,
//        facescan-bench, facescan-site). Prints every problem with its file and line; exit 0 ok, 1 problems.
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';

const [root, ...programArgs] = process.argv.slice(2);
const programs = Object.fromEntries(programArgs.map((a) => a.split(/=(.*)/s).slice(0, 2)));
const problems = [];
const problem = (file, line, text) => problems.push(`${path.relative(root, file)}:${line}: ${text}`);

// --- the programs' help texts ----------------------------------------------------------------------------------
const helpOf = (program, sub) => {
  const args = sub ? [sub, '--help'] : ['--help'];
  try {
    return execFileSync(programs[program], args, { encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe'] });
  } catch (error) {
    return `${error.stdout ?? ''}${error.stderr ?? ''}`;  // some print their help with a usage exit code
  }
};
const helps = {};  // "facescan" or "facescan mesh" -> text
const subcommands = { facescan: [], 'facescan-bench': [], 'facescan-site': ['init', 'add', 'revoke', 'list'] };
for (const program of Object.keys(programs)) helps[program] = helpOf(program);
// Subcommands from the overviews: facescan's "Commands:" list, facescan-bench's "commands:" list.
for (const [program, heading] of [['facescan', /^Commands:$/m], ['facescan-bench', /^commands:$/m]]) {
  const text = helps[program] ?? '';
  const start = text.search(heading);
  if (start < 0) { problems.push(`${program} --help lists no commands`); continue; }
  for (const line of text.slice(start).split('\n').slice(1)) {
    const m = line.match(/^ {2}([a-z]+)\b/);
    if (!m) break;
    subcommands[program].push(m[1]);
  }
  for (const sub of subcommands[program]) helps[`${program} ${sub}`] = helpOf(program, sub);
}
const allHelp = Object.values(helps).join('\n');
const hasOption = (text, option) => new RegExp(`(^|[^a-z0-9-])${option.replace(/[.*+?^${}()|[\]\\]/g, '\\$&')}(?![a-z0-9-])`, 'm').test(text);

// --- the markdown files ----------------------------------------------------------------------------------------
const files = [path.join(root, 'README.md'),
  ...fs.readdirSync(path.join(root, 'docs')).filter((f) => f.endsWith('.md')).map((f) => path.join(root, 'docs', f))];
const slug = (heading) => heading.trim().toLowerCase().replace(/[`*_]/g, (c) => (c === '_' ? '_' : ''))
  .replace(/[^\p{L}\p{N} _-]/gu, '').replace(/ /g, '-');
const anchorsOf = new Map();
const anchors = (file) => {
  if (!anchorsOf.has(file)) {
    const set = new Set();
    let fenced = false;
    for (const line of fs.readFileSync(file, 'utf8').split('\n')) {
      if (line.startsWith('```')) fenced = !fenced;
      const m = !fenced && line.match(/^#{1,6} +(.*)$/);
      if (m) set.add(slug(m[1]));
    }
    anchorsOf.set(file, set);
  }
  return anchorsOf.get(file);
};

const programNames = new Set(Object.keys(programs));
const externalCommands = /^(sudo|cmake|cpack|ctest|apt|apt-get|systemctl|journalctl|editor|git|node|npm|man|top|cd|make|dpkg|ls|cat)$/;
const repoPath = /^(deploy|tests|idl|client_cli|capture_agent|recon_server|cmake|docs)\/[A-Za-z0-9_./@-]*$/;

// One command line as the docs give it: `PROGRAM [SUB] --opt ...`, or options on their own.
function checkCommand(file, lineNo, command) {
  const tokens = command.trim().split(/\s+/).filter(Boolean);
  while (tokens.length && /^[A-Z_][A-Z0-9_]*=/.test(tokens[0])) tokens.shift();  // VAR=value
  if (tokens[0] === 'sudo') tokens.shift();
  if (!tokens.length) return;
  const first = path.basename(tokens[0]);
  const options = tokens.filter((t) => /^--[a-z]/.test(t)).map((t) => t.replace(/[=,.:;)]+.*$|[,.:;)]+$/, ''));
  if (programNames.has(first)) {
    const sub = subcommands[first]?.includes(tokens[1]) ? tokens[1] : null;
    const key = sub && helps[`${first} ${sub}`] !== undefined ? `${first} ${sub}` : first;
    for (const option of options) {
      if (!hasOption(helps[key], option)) problem(file, lineNo, `'${option}' is not in \`${key} --help\` (in: ${command.trim()})`);
    }
  } else if (/^facescan(-[a-z]+)*$/.test(first)) {
    problem(file, lineNo, `'${first}' is no facescan program (in: ${command.trim()})`);
  } else if (tokens[0].startsWith('--')) {
    for (const option of options) {
      if (!hasOption(allHelp, option)) problem(file, lineNo, `'${option}' is in no program's --help (in: ${command.trim()})`);
    }
  }
  // Scripts and other programs (cmake, systemctl, deploy/*.sh): their options are theirs.
}

function checkCode(file, lineNo, code) {
  for (const token of code.split(/[\s`'"(),]+/)) {
    const p = token.replace(/[.:;]+$/, '');
    if (repoPath.test(p) && !p.includes('...') && !/[A-Z]{3,}/.test(p.split('/').pop()) &&
        !fs.existsSync(path.join(root, p))) {
      problem(file, lineNo, `the path '${p}' does not exist in the repository`);
    }
  }
  for (const command of code.split(/\s*(?:&&|\|\||;|\|)\s*/)) checkCommand(file, lineNo, command);
}

for (const file of files) {
  const lines = fs.readFileSync(file, 'utf8').split('\n');
  let fenced = false;
  lines.forEach((line, i) => {
    const lineNo = i + 1;
    if (line.startsWith('```')) { fenced = !fenced; return; }
    if (fenced || /^ {4}\S/.test(line)) {  // a code block: each line a command
      checkCode(file, lineNo, line.replace(/\s#\s.*$/, ''));
      return;
    }
    if ((line.match(/`/g) ?? []).length % 2 === 1) {
      problem(file, lineNo, 'a code span runs across lines: keep it on one line (this check reads spans by line)');
    }
    for (const m of line.matchAll(/`([^`]+)`/g)) checkCode(file, lineNo, m[1]);
    const text = line.replace(/`[^`]*`/g, '');
    for (const m of text.matchAll(/!?\[[^\]]*\]\(([^)\s]+)\)/g)) {
      const target = m[1];
      if (/^[a-z]+:/.test(target)) continue;  // http:, https:, mailto:
      const [where, anchor] = target.split('#');
      const resolved = where ? path.resolve(path.dirname(file), where) : file;
      if (!fs.existsSync(resolved)) { problem(file, lineNo, `link target '${target}' does not exist`); continue; }
      if (anchor && resolved.endsWith('.md') && !anchors(resolved).has(anchor)) {
        problem(file, lineNo, `link '${target}': no heading '#${anchor}' in ${path.relative(root, resolved)}`);
      }
    }
  });
}

for (const program of programNames) {
  if (!helps[program] || !/usage/i.test(helps[program])) problems.push(`${program} --help printed no usage`);
}
if (problems.length) {
  console.log(`docs_check: ${problems.length} problem(s):\n${problems.join('\n')}`);
  process.exit(1);
}
console.log(`docs_check: ${files.length} files: links, images, paths and options of ` +
  `${Object.keys(helps).length} help texts all agree`);
