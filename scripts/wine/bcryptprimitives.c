/*
 * A stand-in for Windows' bcryptprimitives.dll, for wine 8.0, which lacks it.
 *
 * The Rust standard library (1.78 and later) takes its random bytes on Windows from
 * bcryptprimitives.dll's ProcessPrng; without that DLL every Rust .exe fails to start
 * under wine 8.0 (status c0000135). This DLL exports ProcessPrng and forwards it to
 * advapi32's SystemFunction036 (RtlGenRandom), which wine has. Only for running the
 * tests under wine: a real Windows has the DLL. Built by scripts/wine/ensure-wine:
 *
 *   x86_64-w64-mingw32-gcc -shared -O2 -o bcryptprimitives.dll bcryptprimitives.c -ladvapi32
 */
#include <windows.h>

/* RtlGenRandom, exported by advapi32 under this name. */
BOOLEAN WINAPI SystemFunction036(PVOID buffer, ULONG length);

/* Windows' signature: BOOL ProcessPrng(PBYTE pbData, SIZE_T cbData); always TRUE there. */
__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T len)
{
    while (len > 0) {
        ULONG chunk = len > 0x40000000 ? 0x40000000 : (ULONG)len;
        if (!SystemFunction036(data, chunk)) {
            return FALSE;
        }
        data += chunk;
        len -= chunk;
    }
    return TRUE;
}
