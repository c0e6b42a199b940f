#!/usr/bin/python3
"""The image's HEALTHCHECK: asks grpc.health.v1.Health/Check of rpsrd and exits 0 when SERVING.

    grpc_health_check.py [HOST:PORT] [--service NAME] [--timeout SECONDS]

Exit status: 0 SERVING; 1 NOT_SERVING, UNKNOWN or no answer. Plaintext only (as Kubernetes' own
gRPC probes). The messages are encoded by hand, so no generated code is needed: a
HealthCheckRequest is field 1 (service, a string); a HealthCheckResponse field 1 (status, an enum,
SERVING = 1).
"""
import argparse
import sys

import grpc


def encode_request(service: str) -> bytes:
    data = service.encode()
    if not data:
        return b""
    if len(data) > 127:
        raise ValueError("service name too long for this probe")
    return b"\x0a" + bytes([len(data)]) + data


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("target", nargs="?", default="127.0.0.1:50051")
    parser.add_argument("--service", default="")
    parser.add_argument("--timeout", type=float, default=2.0)
    args = parser.parse_args()
    with grpc.insecure_channel(args.target) as channel:
        check = channel.unary_unary("/grpc.health.v1.Health/Check")  # bytes in, bytes out
        try:
            response = check(encode_request(args.service), timeout=args.timeout)
        except grpc.RpcError as error:
            print(f"{args.target}: {error.code().name}: {error.details()}", file=sys.stderr)
            return 1
    serving = response == b"\x08\x01"
    print(f"{args.target}: {'SERVING' if serving else 'not serving (' + response.hex() + ')'}")
    return 0 if serving else 1


if __name__ == "__main__":
    sys.exit(main())
