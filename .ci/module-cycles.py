#!/usr/bin/env python3
"""Fails when modules inside a crate import each other in a loop (directly or through the crate
root's re-exports), printing the loops. Test modules and comments are ignored."""
import re,glob,os,sys
bad=False
for crate in sorted(glob.glob('*/src/lib.rs')):
    root=os.path.dirname(crate)
    mods={}
    owner={}
    lib=open(crate).read()
    for m,grp in re.findall(r'pub(?:\(crate\))? use ([a-z_]+)::\{?([^;]*?)\}?;',lib,flags=re.S):
        for item in grp.split(','):
            item=item.strip().split(' as ')[-1].split('::')[-1]
            if item: owner[item]=m
    for f in glob.glob(root+'/**/*.rs',recursive=True):
        rel=os.path.relpath(f,root)[:-3]
        name=rel.split('/')[0]
        if name in('lib','main'): continue
        src=open(f).read().split('#[cfg(test)]')[0]
        src='\n'.join(l for l in src.split('\n') if not l.strip().startswith('//'))
        deps=set(re.findall(r'crate::([a-z_]+)',src))
        for it in re.findall(r'crate::([A-Za-z_]+)',src):
            if it in owner: deps.add(owner[it])
        for grp in re.findall(r'use crate::\{([^}]*)\}',src,flags=re.S):
            for item in grp.split(','):
                item=item.strip()
                if not item: continue
                head=item.split('::')[0].split(' ')[0]
                deps.add(owner.get(head, head))
        if '/' in rel:
            deps|=set(re.findall(r'super::([a-z_]+)',src))
        mods.setdefault(name,set()).update(d for d in deps if d!=name)
    allm=set(mods)
    def reach(a):
        seen=set();st=[a]
        while st:
            x=st.pop()
            for y in mods.get(x,()):
                if y in allm and y not in seen: seen.add(y);st.append(y)
        return seen
    cyc=sorted(set(tuple(sorted((a,b))) for a in mods for b in mods[a] if b in allm and a in reach(b)))
    if cyc: bad=True
    print(root, 'cycles:', cyc)
sys.exit(1 if bad else 0)
