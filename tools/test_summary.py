"""Add up JUnit XML results below a directory: prints 'tests: N passed, N failed, N skipped'.

Exits 1 if anything failed or errored, or if no test ran at all.
"""
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

passed = failed = skipped = 0
for path in sorted(Path(sys.argv[1]).rglob("*.xml")):
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError:
        print(f"unreadable test result {path}", file=sys.stderr)
        failed += 1
        continue
    for case in root.iter("testcase"):
        if case.find("failure") is not None or case.find("error") is not None:
            failed += 1
            print(f"FAILED: {path.name}: {case.get('classname')}.{case.get('name')}")
        elif case.find("skipped") is not None:
            skipped += 1
        else:
            passed += 1
print(f"tests: {passed} passed, {failed} failed, {skipped} skipped")
sys.exit(1 if failed or passed == 0 else 0)
