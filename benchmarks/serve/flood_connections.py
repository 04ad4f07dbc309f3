#!/usr/bin/env python3
# A flood of idle connections against a running smrdb serve (docs/serve.md, "Transport"):
# opens N connections that send nothing, asks for /v1/databases meanwhile, then counts the
# connections answered 503 at once, held, and closed by the server after its --timeout-ms.
# Usage: flood_connections.py PORT N
import socket, sys, time, resource, urllib.request
port=int(sys.argv[1]); n=int(sys.argv[2])
resource.setrlimit(resource.RLIMIT_NOFILE,(resource.getrlimit(resource.RLIMIT_NOFILE)[1],)*2)
t0=time.time(); socks=[]; failed=0
for i in range(n):
    try:
        s=socket.create_connection(("127.0.0.1",port),timeout=5); socks.append(s)
    except Exception as e: failed+=1
t1=time.time()
# a real request while the flood holds its connections
t2=time.time()
try: code=urllib.request.urlopen(f"http://127.0.0.1:{port}/v1/databases",timeout=10).status
except Exception as e: code=str(e)
t3=time.time()
rej=0; closed=0
for s in socks: s.setblocking(False)
time.sleep(0.5)
for s in socks:
    try:
        d=s.recv(100)
        if d.startswith(b"HTTP/1.1 503"): rej+=1
        elif d==b"": closed+=1
    except BlockingIOError: pass
    except Exception: closed+=1
held=len(socks)-rej-closed
time.sleep(2.5)
closed2=0
for s in socks:
    try:
        d=s.recv(100)
        if d==b"": closed2+=1
    except BlockingIOError: pass
    except Exception: closed2+=1
print(dict(opened=len(socks),connect_failed=failed,open_seconds=round(t1-t0,2),request_during_flood=code,request_ms=round(1000*(t3-t2),1),rejected_503=rej,held_after_0_5s=held,closed_after_3s=closed2))
