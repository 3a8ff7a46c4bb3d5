#!/usr/bin/env python3
"""Import cycles between the files of each Rust crate of the repository (run from anywhere;
`python3 scripts/import-cycles.py [ROOT]`). A file a depends on a file b when a names an item of
b's module (`use` trees and inline crate::/super::/self:: paths, comments and strings left out);
a module and its own ancestors are not counted as depending on each other (a parent declaring and
re-exporting its children is the module tree itself). Prints every strongly connected component
of more than one file with its edges, then the count; exits 1 if there is any."""
import os
import re
import sys

def crates(root):
    out = []
    for dirpath, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if d not in ('target', '.git', '.venv', 'fuzz')]
        if 'Cargo.toml' in files and os.path.isdir(os.path.join(dirpath, 'src')):
            out.append(os.path.join(dirpath, 'src'))
    return out

def modpath(src, f):
    rel = os.path.relpath(f, src)[:-3].split(os.sep)
    if rel[-1] in ('mod', 'lib', 'main'):
        rel = rel[:-1]
    if rel and rel[0] == 'bin':
        return None
    return tuple(rel)

def strip_comments(text):
    text = re.sub(r'/\*.*?\*/', '', text, flags=re.S)
    text = re.sub(r'//[^\n]*', '', text)
    text = re.sub(r'"(?:\\.|[^"\\])*"', '""', text)
    return text

def expand(tree):
    tree = tree.strip()
    # split top-level prefix::{...}
    m = re.match(r'^(.*?)::\s*\{(.*)\}$', tree, flags=re.S)
    if m:
        prefix, inner = m.group(1), m.group(2)
        parts, depth, cur = [], 0, ''
        for ch in inner:
            if ch == '{': depth += 1
            if ch == '}': depth -= 1
            if ch == ',' and depth == 0:
                parts.append(cur); cur = ''
            else:
                cur += ch
        parts.append(cur)
        res = []
        for p in parts:
            p = p.strip()
            if not p: continue
            for e in expand(p):
                res.append(prefix + '::' + e if e != 'self' else prefix)
        return res
    tree = re.sub(r'\s+as\s+\w+$', '', tree)
    return [tree]

def paths_of(text):
    text = strip_comments(text)
    out = []
    for m in re.finditer(r'\buse\s+([^;]+);', text):
        out += expand(re.sub(r'\s+', ' ', m.group(1)))
    for m in re.finditer(r'\b((?:crate|super|self)(?:::(?:super|\w+))+)', text):
        out.append(m.group(1))
    return out

def resolve(cur, path, modules):
    segs = path.replace(' ', '').split('::')
    if segs[0] == 'crate':
        base, segs = [], segs[1:]
    elif segs[0] in ('super', 'self'):
        base = list(cur)
        while segs and segs[0] in ('super', 'self'):
            if segs[0] == 'super':
                if not base: return None
                base.pop()
            segs = segs[1:]
    else:
        # relative to the current module (child module names) or an external crate
        base = list(cur)
        if tuple(base + segs[:1]) not in modules:
            return None
    full = base + segs
    for n in range(len(full), -1, -1):
        if tuple(full[:n]) in modules:
            return tuple(full[:n])
    return None

def main(root):
    total = []
    for src in sorted(crates(root)):
        files = []
        for dp, _, fs in os.walk(src):
            for f in fs:
                if f.endswith('.rs'):
                    files.append(os.path.join(dp, f))
        modules = {}
        for f in files:
            mp = modpath(src, f)
            if mp is not None:
                modules[mp] = f
        edges = {m: set() for m in modules}
        for mp, f in modules.items():
            text = open(f, encoding='utf-8').read()
            for p in paths_of(text):
                t = resolve(mp, p, modules)
                if t is None or t == mp: continue
                if t[:len(mp)] == mp or mp[:len(t)] == t: continue
                edges[mp].add(t)
        # Tarjan
        index, low, stack, on, sccs, counter = {}, {}, [], set(), [], [0]
        sys.setrecursionlimit(10000)
        def strong(v):
            index[v] = low[v] = counter[0]; counter[0] += 1
            stack.append(v); on.add(v)
            for w in edges[v]:
                if w not in index:
                    strong(w); low[v] = min(low[v], low[w])
                elif w in on:
                    low[v] = min(low[v], index[w])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop(); on.discard(w); comp.append(w)
                    if w == v: break
                if len(comp) > 1: sccs.append(comp)
        for v in modules:
            if v not in index: strong(v)
        for comp in sccs:
            names = sorted(os.path.relpath(modules[m], root) for m in comp)
            links = []
            for a in comp:
                for b in edges[a]:
                    if b in comp:
                        links.append(f"{os.path.relpath(modules[a], root)} -> {os.path.relpath(modules[b], root)}")
            total.append((names, sorted(links)))
    for names, links in total:
        print('cycle:', ' <-> '.join(names))
        for l in links: print('   ', l)
    print(f'{len(total)} import cycles')
    return len(total)

if __name__ == '__main__':
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
    sys.exit(1 if main(root) else 0)
