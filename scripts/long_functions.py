#!/usr/bin/env python3
"""Function bodies over N lines in C++ sources, for issue 27's "no function on a
core path over 120 lines": a signature may span lines; a lambda or local class
counts inside its function; strings, raw strings, chars and comments are
skipped. Lines are counted from the signature's first line to the closing brace.

Usage: scripts/long_functions.py 120 assessment cli db executors orchestrator ...
Prints "LINES FILE:LINE NAME", one function per line."""
import re, sys, pathlib
limit = int(sys.argv[1]); roots = sys.argv[2:]
def strip(text):
    out=[]; i=0; n=len(text)
    while i<n:
        c=text[i]
        if text.startswith('//',i):
            j=text.find('\n',i); j=n if j<0 else j; i=j; continue
        if text.startswith('/*',i):
            j=text.find('*/',i+2); j=n if j<0 else j+2; out.append('\n'*text.count('\n',i,j)); i=j; continue
        m=re.match(r'R"([^(]*)\(',text[i:i+40])
        if m:
            end=')'+m.group(1)+'"'; j=text.find(end,i); j=n if j<0 else j+len(end)
            out.append('""'+'\n'*text.count('\n',i,j)); i=j; continue
        if c in '"\'':
            j=i+1
            while j<n and text[j]!=c:
                j+= 2 if text[j]=='\\' else 1
            out.append(c+c); i=j+1; continue
        out.append(c); i+=1
    return ''.join(out)
for root in roots:
  for p in sorted(pathlib.Path(root).rglob('*.cpp')):
    t=strip(p.read_text())
    depth=0; stack=[]; stmt_start=0; line=1; i=0
    header=''
    for idx,ch in enumerate(t):
        if ch=='\n': line+=1
        if ch=='{':
            sig=header.strip()
            is_fn = bool(re.search(r'\)\s*(const)?\s*(noexcept)?\s*(override)?\s*(->\s*[\w:<>,\s*&]+)?\s*(:\s*[^{;]*)?$', sig)) and not re.match(r'^(namespace|struct|class|enum|union|if|for|while|switch|else|do|catch|try)\b', sig.split('\n')[-1].strip()) and not re.search(r'\b(if|for|while|switch|catch)\s*\(', sig.split('\n')[0] if sig else '') and '=' not in sig.split('(')[0]
            first = line - sig.count('\n')
            name = re.findall(r'([\w:~]+)\s*\(', sig)
            stack.append((is_fn and not any(s[0] for s in stack), first, name[0] if name else '?'))
            header=''
        elif ch=='}':
            if stack:
                fn,first,name=stack.pop()
                if fn and line-first+1>limit:
                    print(f'{line-first+1:5d} {p}:{first} {name}')
            header=''
        elif ch==';':
            header=''
        else:
            header+=ch
